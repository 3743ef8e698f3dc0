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

/// Ruge–Stüben first pass: the coarse index of every C unknown (`NONE` for F) and their
/// number.
pub(super) fn split(g: &impl Rows, wmax: &[f64]) -> (Vec<u32>, usize) {
    let n = g.n();
    const UNDECIDED: u8 = 0;
    const C: u8 = 1;
    const F: u8 = 2;
    // λ_i: unknowns that depend strongly on i (i strongly influences j: w_ji ≥ θ max_k w_jk).
    let mut lambda: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            // w_ji = w_ij (symmetric).
            g.row(i)
                .filter(|&(j, w)| strong(w, wmax[j as usize]))
                .count() as u32
        })
        .collect();
    let mut state = vec![UNDECIDED; n];
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
        for (j, wij) in g.row(i) {
            let j = j as usize;
            if state[j] != UNDECIDED || !strong(wij, wmax[j]) {
                continue;
            }
            unlink(j, lambda[j] as usize, &mut head, &mut next, &mut prev);
            state[j] = F;
            for (k, wjk) in g.row(j) {
                let k = k as usize;
                if state[k] != UNDECIDED || !strong(wjk, wmax[j]) {
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
        for (k, wik) in g.row(i) {
            let k = k as usize;
            if state[k] != UNDECIDED || !strong(wik, wmax[i]) {
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
    // Second pass, in unknown order: a strong F neighbour `k` of an F unknown `i` that is
    // joined to none of the strong C neighbours of `i` becomes C (else the interpolation to
    // `i` would have to lump `w_ik` into its diagonal).
    let mut ci: Vec<u32> = Vec::new();
    for i in 0..n {
        if state[i] != F {
            continue;
        }
        ci.clear();
        for (j, wij) in g.row(i) {
            if state[j as usize] == C && strong(wij, wmax[i]) {
                ci.push(j);
            }
        }
        for (k, wik) in g.row(i) {
            let k = k as usize;
            if state[k] != F || !strong(wik, wmax[i]) {
                continue;
            }
            if !ci.iter().any(|&m| g.weight(k, m) > 0.0) {
                state[k] = C;
                ci.push(k as u32);
            }
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
