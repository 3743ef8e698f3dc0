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
    split_with(g, wmax, block, true, NEAR_CAP)
}

/// [`split_in_blocks`]; `sift`: the second pass visits only the F unknowns left uncovered
/// by the first (else every F unknown: the same split, tested); `near_cap`: neighbours a
/// row's record holds in the first pass, at most [`NEAR_CAP`] (fewer, down to 0, read more
/// rows from the operator: the same split, tested).
pub(super) fn split_with(
    g: &impl Rows,
    wmax: &[f64],
    block: usize,
    sift: bool,
    near_cap: usize,
) -> (Vec<u32>, usize) {
    let n = g.n();
    let mut state = vec![UNDECIDED; n];
    state
        .par_chunks_mut(block)
        .enumerate()
        .for_each(|(b, st)| first_pass(g, wmax, b * block, st, near_cap));
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

/// An undecided unknown's place in the buckets of the first pass: its neighbours in its
/// bucket's list and its weight λ side by side, so that moving it between buckets touches
/// one place in memory for it (three separate arrays took a cache miss for each).
#[derive(Clone, Copy)]
struct Node {
    next: u32,
    prev: u32,
    lambda: u32,
}

/// Buckets of undecided unknowns by λ: doubly linked lists, each listing the unknowns most
/// recently put in it first.
struct Buckets {
    head: Vec<u32>,
    node: Vec<Node>,
}

impl Buckets {
    #[inline(always)]
    fn unlink(&mut self, i: usize) {
        let Node { next, prev, lambda } = self.node[i];
        if prev != NONE {
            self.node[prev as usize].next = next;
        } else {
            self.head[lambda as usize] = next;
        }
        if next != NONE {
            self.node[next as usize].prev = prev;
        }
    }

    /// Puts unlinked unknown `i` first in bucket `l` (λ_i = l).
    #[inline(always)]
    fn push(&mut self, i: usize, l: usize) {
        if l >= self.head.len() {
            let cap = (2 * self.head.len()).max(l + 1);
            self.head.resize(cap, NONE);
        }
        let h = self.head[l];
        self.node[i] = Node {
            next: h,
            prev: NONE,
            lambda: l as u32,
        };
        if h != NONE {
            self.node[h as usize].prev = i as u32;
        }
        self.head[l] = i as u32;
    }
}

/// Neighbours a [`Near`] record holds.
pub(super) const NEAR_CAP: usize = 12;

/// One unknown's strong relations inside its block for the first pass, in one 32-byte
/// record: its neighbours as offsets from it, in the row's order, each flagged as depending
/// strongly on it (`dep`: `w_ij ≥ θ max_k w_jk`) and as influencing it strongly (`infl`:
/// `w_ij ≥ θ max_k w_ik`). The first pass visits rows in the order the greedy choice
/// dictates, far apart in memory: each visit of a compressed row cost cache misses on its
/// row pointer, columns, weights and the neighbours' largest faces, where a record is 32
/// aligned bytes, within one cache line.
#[derive(Clone, Copy, Default)]
#[repr(C, align(32))]
struct Near {
    /// The row does not fit a record (more than [`NEAR_CAP`] neighbours in the block, or
    /// one farther than an `i16` offset): it is read from the operator instead.
    long: bool,
    dep: u16,
    infl: u16,
    off: [i16; NEAR_CAP],
}

/// The strong relations of the first pass: records, and the operator for the long rows.
struct Strong<'a, G: Rows> {
    g: &'a G,
    wmax: &'a [f64],
    i0: usize,
    near: Vec<Near>,
}

impl<'a, G: Rows> Strong<'a, G> {
    /// Records of the unknowns `i0..i0 + n`, each of at most `cap` (≤ [`NEAR_CAP`])
    /// neighbours.
    fn new(g: &'a G, wmax: &'a [f64], i0: usize, n: usize, cap: usize) -> Self {
        let cap = cap.min(NEAR_CAP);
        let near = (0..n)
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|t| {
                let i = i0 + t;
                let mut r = Near::default();
                let mut e = 0;
                for (j, w) in g.row(i) {
                    if (j as usize).wrapping_sub(i0) >= n {
                        continue;
                    }
                    let d = j as i64 - i as i64;
                    if e == cap || d < i16::MIN as i64 || d > i16::MAX as i64 {
                        return Near {
                            long: true,
                            ..Near::default()
                        };
                    }
                    r.off[e] = d as i16;
                    if strong(w, wmax[j as usize]) {
                        r.dep |= 1 << e;
                    }
                    if strong(w, wmax[i]) {
                        r.infl |= 1 << e;
                    }
                    e += 1;
                }
                r
            })
            .collect();
        Strong { g, wmax, i0, near }
    }

    /// The unknowns (block indices) that depend strongly on `t` (`dep`) or that `t` depends
    /// on strongly, in the row's order, into `out`.
    #[inline(always)]
    fn list(&self, t: usize, dep: bool, out: &mut Vec<u32>) {
        out.clear();
        let r = &self.near[t];
        if !r.long {
            let mut m = if dep { r.dep } else { r.infl };
            while m != 0 {
                let e = m.trailing_zeros() as usize;
                m &= m - 1;
                out.push((t as i64 + i64::from(r.off[e])) as u32);
            }
            return;
        }
        let (i0, n, i) = (self.i0, self.near.len(), self.i0 + t);
        for (j, w) in self.g.row(i) {
            if (j as usize).wrapping_sub(i0) >= n {
                continue;
            }
            let by = if dep {
                self.wmax[j as usize]
            } else {
                self.wmax[i]
            };
            if strong(w, by) {
                out.push(j - i0 as u32);
            }
        }
    }

    /// How many unknowns of the block depend strongly on `t`.
    fn dependents(&self, t: usize, buf: &mut Vec<u32>) -> u32 {
        let r = &self.near[t];
        if !r.long {
            return r.dep.count_ones();
        }
        self.list(t, true, buf);
        buf.len() as u32
    }
}

/// Asks for `v[i]`'s cache line ahead of its use (a hint only: no effect on any value).
#[inline(always)]
fn prefetch<T>(v: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch of any address is only a hint; it neither faults nor reads.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(v.as_ptr().wrapping_add(i).cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (v, i);
}

/// Ruge–Stüben first pass on the unknowns `i0..i0 + state.len()` and the strong faces
/// between them, sequential in unknown order: repeatedly the undecided unknown on which
/// most undecided ones depend strongly becomes C and its strong dependents F.
fn first_pass(g: &impl Rows, wmax: &[f64], i0: usize, state: &mut [u8], near_cap: usize) {
    let n = state.len();
    let sr = Strong::new(g, wmax, i0, n, near_cap);
    // λ_i: unknowns of the block that depend strongly on i (i strongly influences j:
    // w_ji ≥ θ max_k w_jk; w_ji = w_ij, symmetric).
    let lambda: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map_init(Vec::new, |buf, t| sr.dependents(t, buf))
        .collect();
    let top0 = lambda.iter().copied().max().unwrap_or(0) as usize;
    let mut b = Buckets {
        head: vec![NONE; (top0 + 1).max(16)],
        node: vec![
            Node {
                next: NONE,
                prev: NONE,
                lambda: 0,
            };
            n
        ],
    };
    // Inserted in reverse so that each bucket lists unknowns in ascending order.
    for i in (0..n).rev() {
        b.push(i, lambda[i] as usize);
    }
    drop(lambda);
    let (mut deps, mut infl) = (Vec::new(), Vec::new());
    let mut top = top0;
    loop {
        while top > 0 && b.head[top] == NONE {
            top -= 1;
        }
        let i = b.head[top];
        if i == NONE {
            break;
        }
        let i = i as usize;
        b.unlink(i);
        state[i] = C;
        // Strong dependents of i become F; their strong influencers gain weight.
        sr.list(i, true, &mut deps);
        for &j in &deps {
            prefetch(&sr.near, j as usize);
            prefetch(&b.node, j as usize);
        }
        for &j in &deps {
            let j = j as usize;
            if state[j] != UNDECIDED {
                continue;
            }
            b.unlink(j);
            state[j] = F;
            sr.list(j, false, &mut infl);
            for &k in &infl {
                prefetch(&b.node, k as usize);
            }
            for &k in &infl {
                let k = k as usize;
                if state[k] != UNDECIDED {
                    continue;
                }
                let l = b.node[k].lambda as usize + 1;
                b.unlink(k);
                b.push(k, l);
                if l >= top {
                    // Likely the next C unknown: its record is read first thing then.
                    prefetch(&sr.near, k);
                }
                top = top.max(l);
            }
        }
        // Unknowns that strongly influence i lose weight.
        sr.list(i, false, &mut infl);
        for &k in &infl {
            let k = k as usize;
            if state[k] != UNDECIDED {
                continue;
            }
            let l = b.node[k].lambda as usize;
            if l == 0 {
                continue;
            }
            b.unlink(k);
            b.push(k, l - 1);
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
