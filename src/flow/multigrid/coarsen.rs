//! Strength of connection and the Ruge–Stüben C/F splitting (both passes).

use rayon::prelude::*;

use super::rows::Rows;
use super::{CHUNK, NONE, THETA};

/// Largest positive face of every row.
pub(super) fn strongest(g: &impl Rows) -> Vec<f64> {
    (0..g.n())
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| g.row(i).fold(0.0, |m: f64, (_, w)| m.max(w)))
        .collect()
}

/// Whether `w` (a face of a row whose largest face is `wmax`) is strong.
#[inline(always)]
pub(super) fn strong(w: f64, wmax: f64) -> bool {
    w > 0.0 && w >= THETA * wmax
}

const UNDECIDED: u8 = 0;
const C: u8 = 1;
const F: u8 = 2;

/// Unknowns per block of the splitting: each block is split on its own (in parallel), so
/// the C/F split depends on the block boundaries only, never on the thread count. Unknowns
/// are numbered in grid order, so a block is a band of whole grid rows (blocks of 2^18:
/// about 100 rows at 4097²). One block (the sequential splitting) by default: on the 4097²
/// gap blocks of 2^18 took 58 CG iterations instead of 42 for some 10 s less setup
/// (docs/flow.md).
pub(super) const SPLIT_BLOCK: usize = usize::MAX;

/// Ruge–Stüben splitting: the coarse index of every C unknown (`NONE` for F) and their
/// number. Both passes run on fixed blocks of [`SPLIT_BLOCK`] unknowns in parallel, the
/// first on each block's own strong faces, the second with the first pass's states outside
/// the block; the strong F pairs across a boundary are checked last, in unknown order.
pub(super) fn split(g: &impl Rows, wmax: &[f64]) -> (Vec<u32>, usize) {
    split_in_blocks(g, wmax, SPLIT_BLOCK)
}

/// [`split`] with blocks of `block` unknowns.
pub(super) fn split_in_blocks(g: &impl Rows, wmax: &[f64], block: usize) -> (Vec<u32>, usize) {
    split_with(g, wmax, block, true)
}

/// [`split_in_blocks`]; `sift`: the second pass visits only the F unknowns left uncovered
/// by the first (else every F unknown: the same split, tested).
pub(super) fn split_with(
    g: &impl Rows,
    wmax: &[f64],
    block: usize,
    sift: bool,
) -> (Vec<u32>, usize) {
    let n = g.n();
    let mut state = vec![UNDECIDED; n];
    state
        .par_chunks_mut(block)
        .enumerate()
        .for_each(|(b, st)| first_pass(g, wmax, b * block, st));
    // Second pass: a strong F neighbour `k` of an F unknown `i` that is joined to none of
    // the strong C neighbours of `i` becomes C (else the interpolation to `i` would have to
    // lump `w_ik` into its diagonal). Inside each block in unknown order, other blocks'
    // unknowns as the first pass left them (a C stays C, so a common C neighbour found
    // stays one); pairs with `k` in another block are kept for the end.
    let first = state.clone();
    // The second pass only turns F unknowns into C: an F unknown's strong C neighbours only
    // grow and its strong F neighbours only shrink, so one without an uncovered strong F
    // neighbour after the first pass has none later. Found in parallel, only the others are
    // visited in order (the same split as visiting all).
    let open: Vec<bool> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| first[i] == F && (!sift || uncovered(g, wmax, i, &first)))
        .collect();
    let deferred: Vec<(u32, u32)> = state
        .par_chunks_mut(block)
        .zip(open.par_chunks(block))
        .enumerate()
        .flat_map_iter(|(b, (st, op))| second_pass(g, wmax, b * block, st, &first, op))
        .collect();
    drop(open);
    drop(first);
    let mut ci: Vec<u32> = Vec::new();
    for &(i, k) in &deferred {
        let (i, k) = (i as usize, k as usize);
        if state[i] != F || state[k] != F {
            continue;
        }
        ci.clear();
        ci.extend(
            g.row(i)
                .filter(|&(j, w)| state[j as usize] == C && strong(w, wmax[i]))
                .map(|(j, _)| j),
        );
        if !ci.iter().any(|&m| g.weight(k, m) > 0.0) {
            state[k] = C;
        }
    }
    let mut cidx = vec![NONE; n];
    let mut nc = 0u32;
    for i in 0..n {
        if state[i] == C {
            cidx[i] = nc;
            nc += 1;
        }
    }
    (cidx, nc as usize)
}

/// Ruge–Stüben first pass on the unknowns `i0..i0 + state.len()` and the strong faces
/// between them, sequential in unknown order: repeatedly the undecided unknown on which
/// most undecided ones depend strongly becomes C and its strong dependents F.
fn first_pass(g: &impl Rows, wmax: &[f64], i0: usize, state: &mut [u8]) {
    let n = state.len();
    let inside = |j: u32| (j as usize).wrapping_sub(i0) < n;
    // λ_i: unknowns of the block that depend strongly on i (i strongly influences j:
    // w_ji ≥ θ max_k w_jk; w_ji = w_ij, symmetric).
    let mut lambda: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|t| {
            g.row(i0 + t)
                .filter(|&(j, w)| inside(j) && strong(w, wmax[j as usize]))
                .count() as u32
        })
        .collect();
    // Buckets of undecided unknowns by λ: doubly linked lists.
    let top0 = lambda.iter().copied().max().unwrap_or(0) as usize;
    let mut cap = (top0 + 1).max(16);
    let mut head = vec![NONE; cap];
    let mut next = vec![NONE; n];
    let mut prev = vec![NONE; n];
    // Insert in reverse so that each bucket lists unknowns in ascending order.
    for i in (0..n).rev() {
        let l = lambda[i] as usize;
        next[i] = head[l];
        if head[l] != NONE {
            prev[head[l] as usize] = i as u32;
        }
        head[l] = i as u32;
    }
    let unlink = |i: usize, l: usize, head: &mut [u32], next: &mut [u32], prev: &mut [u32]| {
        let (pv, nx) = (prev[i], next[i]);
        if pv != NONE {
            next[pv as usize] = nx;
        } else {
            head[l] = nx;
        }
        if nx != NONE {
            prev[nx as usize] = pv;
        }
        prev[i] = NONE;
        next[i] = NONE;
    };
    let mut top = top0;
    loop {
        while top > 0 && head[top] == NONE {
            top -= 1;
        }
        let i = head[top];
        if i == NONE {
            break;
        }
        let i = i as usize;
        unlink(i, top, &mut head, &mut next, &mut prev);
        state[i] = C;
        // Strong dependents of i become F; their strong influencers gain weight.
        for (j, wij) in g.row(i0 + i) {
            if !inside(j) {
                continue;
            }
            let j = j as usize - i0;
            if state[j] != UNDECIDED || !strong(wij, wmax[i0 + j]) {
                continue;
            }
            unlink(j, lambda[j] as usize, &mut head, &mut next, &mut prev);
            state[j] = F;
            for (k, wjk) in g.row(i0 + j) {
                if !inside(k) {
                    continue;
                }
                let k = k as usize - i0;
                if state[k] != UNDECIDED || !strong(wjk, wmax[i0 + j]) {
                    continue;
                }
                let l = lambda[k] as usize;
                unlink(k, l, &mut head, &mut next, &mut prev);
                lambda[k] += 1;
                let l = l + 1;
                if l >= cap {
                    cap *= 2;
                    head.resize(cap, NONE);
                }
                next[k] = head[l];
                if head[l] != NONE {
                    prev[head[l] as usize] = k as u32;
                }
                head[l] = k as u32;
                top = top.max(l);
            }
        }
        // Unknowns that strongly influence i lose weight.
        for (k, wik) in g.row(i0 + i) {
            if !inside(k) {
                continue;
            }
            let k = k as usize - i0;
            if state[k] != UNDECIDED || !strong(wik, wmax[i0 + i]) {
                continue;
            }
            let l = lambda[k] as usize;
            if l == 0 {
                continue;
            }
            unlink(k, l, &mut head, &mut next, &mut prev);
            lambda[k] -= 1;
            let l = l - 1;
            next[k] = head[l];
            if head[l] != NONE {
                prev[head[l] as usize] = k as u32;
            }
            head[l] = k as u32;
        }
    }
}

/// Whether F unknown `i` has a strong F neighbour joined to none of its strong C neighbours
/// (in `state`).
fn uncovered(g: &impl Rows, wmax: &[f64], i: usize, state: &[u8]) -> bool {
    let strong_c = || {
        g.row(i)
            .filter(|&(j, w)| state[j as usize] == C && strong(w, wmax[i]))
            .map(|(j, _)| j)
    };
    g.row(i).any(|(k, w)| {
        state[k as usize] == F
            && strong(w, wmax[i])
            && !strong_c().any(|m| g.weight(k as usize, m) > 0.0)
    })
}

/// Ruge–Stüben second pass on the unknowns `i0..i0 + state.len()` in unknown order (the
/// other blocks' unknowns read from `first`), visiting only those marked in `open`
/// ([`uncovered`] after the first pass); the strong F pairs `(i, k)` with `k` outside the
/// block, for the final check.
fn second_pass(
    g: &impl Rows,
    wmax: &[f64],
    i0: usize,
    state: &mut [u8],
    first: &[u8],
    open: &[bool],
) -> Vec<(u32, u32)> {
    let n = state.len();
    let mut deferred = Vec::new();
    let mut ci: Vec<u32> = Vec::new();
    for t in 0..n {
        if !open[t] || state[t] != F {
            continue;
        }
        let i = i0 + t;
        let at = |state: &[u8], j: usize| {
            if j.wrapping_sub(i0) < n {
                state[j - i0]
            } else {
                first[j]
            }
        };
        ci.clear();
        for (j, wij) in g.row(i) {
            if at(state, j as usize) == C && strong(wij, wmax[i]) {
                ci.push(j);
            }
        }
        for (k, wik) in g.row(i) {
            let k = k as usize;
            if at(state, k) != F || !strong(wik, wmax[i]) {
                continue;
            }
            if !ci.iter().any(|&m| g.weight(k, m) > 0.0) {
                if k.wrapping_sub(i0) < n {
                    state[k - i0] = C;
                    ci.push(k as u32);
                } else {
                    deferred.push((i as u32, k as u32));
                }
            }
        }
    }
    deferred
}
