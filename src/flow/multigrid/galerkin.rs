//! Galerkin coarse operator `Pᵀ A P` with the reservoir part rebuilt without cancellation.

use rayon::prelude::*;

use super::rows::Rows;
use super::{concat, Graph, Interp, RowBlock, CHUNK, NONE};

/// Galerkin coarse operator `Pᵀ A P` in conductance form (module docs).
pub(super) fn galerkin(g: &impl Rows, ip: &Interp, delta: &[f64], nc: usize) -> Graph {
    // (A (P 1))_i = dir_i (1 − δ_i) − Σ_k w_ik (δ_i − δ_k): exactly 0 away from reservoirs.
    let a1: Vec<f64> = (0..g.n())
        .into_par_iter()
        .with_min_len(CHUNK)
        .map(|i| {
            let mut v = g.reservoir(i) * (1.0 - delta[i]);
            for (k, wik) in g.row(i) {
                let k = k as usize;
                if delta[i] != delta[k] {
                    v -= wik * (delta[i] - delta[k]);
                }
            }
            v
        })
        .collect();
    // Each task's row accumulator: `slot[c]` is the position of coarse column `c` in the
    // row being built (NONE when absent); the row's entries keep the order of first touch,
    // so every sum is taken in an order fixed by the matrices, not by the threads.
    let nblocks = nc.div_ceil(CHUNK);
    // Few splits: each allocates an accumulator of the coarse size (rows are independent,
    // so the split does not change any value).
    let per = nblocks.div_ceil(4 * rayon::current_num_threads()).max(1);
    let blocks: Vec<RowBlock> = (0..nblocks)
        .into_par_iter()
        .with_min_len(per)
        .map_init(
            || vec![NONE; nc],
            |slot, blk| {
                let rows = blk * CHUNK..((blk + 1) * CHUNK).min(nc);
                let mut len = Vec::with_capacity(rows.len());
                let mut col = Vec::new();
                let mut w = Vec::new();
                let mut dir = Vec::with_capacity(rows.len());
                let mut acc: Vec<(u32, f64)> = Vec::new();
                for ci in rows {
                    acc.clear();
                    let mut res = 0.0;
                    let mut add = |acc: &mut Vec<(u32, f64)>, c: u32, v: f64| {
                        let s = &mut slot[c as usize];
                        if *s == NONE {
                            *s = acc.len() as u32;
                            acc.push((c, v));
                        } else {
                            acc[*s as usize].1 += v;
                        }
                    };
                    for t in ip.tptr[ci]..ip.tptr[ci + 1] {
                        let i = ip.trow[t] as usize;
                        let pi = f64::from(ip.tval[t]);
                        res += pi * a1[i];
                        // (A P)(i, J) = d_i P_iJ − Σ_k w_ik P_kJ, for J ≠ ci.
                        let di = g.diag(i);
                        for p in ip.ptr[i]..ip.ptr[i + 1] {
                            let cj = ip.col[p];
                            if cj as usize != ci {
                                add(&mut acc, cj, pi * di * f64::from(ip.val[p]));
                            }
                        }
                        for (k, wik) in g.row(i) {
                            let k = k as usize;
                            let f = pi * wik;
                            for p in ip.ptr[k]..ip.ptr[k + 1] {
                                let cj = ip.col[p];
                                if cj as usize != ci {
                                    add(&mut acc, cj, -f * f64::from(ip.val[p]));
                                }
                            }
                        }
                    }
                    for e in acc.iter() {
                        slot[e.0 as usize] = NONE;
                    }
                    // Stored in single precision: an entry that rounds to 0 is dropped.
                    acc.retain(|e| e.1 as f32 != 0.0);
                    acc.sort_unstable_by_key(|e| e.0);
                    len.push(acc.len());
                    for &(c, v) in acc.iter() {
                        col.push(c);
                        w.push(-v as f32);
                    }
                    dir.push(res.max(0.0));
                }
                (len, col, w, dir)
            },
        )
        .collect();
    let (ptr, col, w, dir) = concat(blocks);
    Graph::from_faces(ptr, col, w, dir)
}
