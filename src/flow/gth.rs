//! Elimination of the Reynolds system without cancellation, for gaps whose conductances span
//! more decades than a double can subtract (the star–mesh transform with the pivots of
//! Grassmann, Taksar and Heyman).
//!
//! The operator is a conductance network: faces `c_ij > 0` between cells and a conductance
//! `s_i ≥ 0` to the reservoirs, with diagonal `d_i = s_i + Σ_j c_ij`. Stored as a rounded
//! diagonal, `d_i` loses the faces below `ε d_i`: a region of wide gaps joined to the rest only
//! through necks `10⁻¹⁶` times narrower in conductance has a diagonal equal to its internal
//! faces, a singular block, and the Cholesky factor of the assembled matrix returns a
//! non-positive pivot or a flow rate off by any factor.
//!
//! Eliminating cell `p` replaces its star by a mesh: every pair of its remaining neighbours
//! `i, j` gains the face `c_pi c_pj / d_p` and each neighbour `i` gains `c_pi s_p / d_p`
//! towards the reservoirs. The pivot is recomputed as `d_p = s_p + Σ_j c_pj`, and every
//! update is a sum of positive terms: nothing cancels. With a right-hand side `b ≥ 0` (a
//! reservoir at unit pressure) the forward and backward substitutions are sums of positive
//! terms too, so every pressure, and the flow rate `b_out · φ`, has a relative error of a
//! few `n ε` however widely the conductances spread.
//!
//! The elimination order is the Cholesky solver's without its blocks on large pieces
//! ([`super::order::elimination_ordering`]).

use super::assemble::Stencil;
use super::order;
use crate::error::{Error, Result};

/// The eliminated network: for each unknown in elimination order its pivot and the
/// neighbours (positions later in the order) with their conductances at elimination.
pub struct Elimination {
    /// Grid cell of each position.
    cells: Vec<usize>,
    pivot: Vec<f64>,
    col_ptr: Vec<usize>,
    col_idx: Vec<u32>,
    /// `c_pi / d_p` of each stored neighbour.
    col_w: Vec<f64>,
}

/// Largest system eliminated (about a minute at 1024², against a second for the factor).
pub const MAX_UNKNOWNS: usize = 1 << 20;

/// Bytes per stored neighbour (index and weight) during the elimination, with room for the
/// working adjacency lists.
const BYTES_PER_ENTRY: u64 = 40;

impl Elimination {
    /// Eliminates the active cells of `st` (faces `e`, `s` and reservoir conductances `dir`;
    /// the rounded diagonal `d` is not used). Refuses with [`Error::TooLarge`] once the
    /// fill would need more than `memory_limit` bytes.
    pub fn new(st: &Stencil, memory_limit: Option<u64>) -> Result<Self> {
        let n = st.ny * st.nx;
        let mut index = vec![usize::MAX; n];
        let mut cells0 = Vec::new();
        for (k, slot) in index.iter_mut().enumerate() {
            if st.active[k] {
                *slot = cells0.len();
                cells0.push(k);
            }
        }
        let m = cells0.len();
        if m > MAX_UNKNOWNS {
            return Err(Error::TooLarge {
                bytes: BYTES_PER_ENTRY * 64 * m as u64,
                limit: BYTES_PER_ENTRY * 64 * MAX_UNKNOWNS as u64,
                what: format!("the cancellation-free elimination of {m} flow unknowns"),
            });
        }
        let order = order::elimination_ordering(st, &index, m);
        // Position of each unknown in the order.
        let mut pos = vec![0u32; m];
        for (p, &u) in order.iter().enumerate() {
            pos[u] = p as u32;
        }
        let cells: Vec<usize> = order.iter().map(|&u| cells0[u]).collect();
        drop(cells0);
        let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); m];
        let mut excess = vec![0.0; m];
        for (p, &k) in cells.iter().enumerate() {
            excess[p] = st.dir[k];
            st.for_each_face(k, |l, c| {
                let q = pos[index[l]];
                // A 2-wide periodic row joins the same pair by two faces: add them.
                if let Some(e) = adj[p].iter_mut().find(|e| e.0 == q) {
                    e.1 += c;
                } else {
                    adj[p].push((q, c));
                }
            });
        }
        drop(index);
        drop(pos);
        let mut pivot = vec![0.0; m];
        let mut col_ptr = Vec::with_capacity(m + 1);
        let mut col_idx: Vec<u32> = Vec::new();
        let mut col_w: Vec<f64> = Vec::new();
        col_ptr.push(0);
        // Slot of each neighbour in the list being updated (u32::MAX: none).
        let mut slot = vec![u32::MAX; m];
        let mut live: u64 = adj.iter().map(|a| a.len() as u64).sum();
        for p in 0..m {
            let star = std::mem::take(&mut adj[p]);
            let d = excess[p] + star.iter().map(|e| e.1).sum::<f64>();
            pivot[p] = d;
            for &(i, c) in &star {
                let w = c / d;
                col_idx.push(i);
                col_w.push(w);
                excess[i as usize] += w * excess[p];
            }
            col_ptr.push(col_idx.len());
            // Mesh among the neighbours: c_ij += c_pi (c_pj / d_p); p leaves each list.
            for &(i, ci) in &star {
                let list = &mut adj[i as usize];
                list.retain(|e| e.0 != p as u32);
                for (t, e) in list.iter().enumerate() {
                    slot[e.0 as usize] = t as u32;
                }
                for &(j, cj) in &star {
                    if j == i {
                        continue;
                    }
                    let add = ci * (cj / d);
                    match slot[j as usize] {
                        u32::MAX => {
                            slot[j as usize] = list.len() as u32;
                            list.push((j, add));
                            live += 1;
                        }
                        t => list[t as usize].1 += add,
                    }
                }
                for e in list.iter() {
                    slot[e.0 as usize] = u32::MAX;
                }
            }
            // p's own list and its entry in each neighbour's list are gone.
            live = live.saturating_sub(2 * star.len() as u64);
            if let Some(limit) = memory_limit {
                let need = BYTES_PER_ENTRY * (live + col_idx.len() as u64) + 48 * m as u64;
                if need > limit {
                    return Err(Error::TooLarge {
                        bytes: need,
                        limit,
                        what: format!("the cancellation-free elimination of {m} flow unknowns"),
                    });
                }
            }
        }
        Ok(Elimination {
            cells,
            pivot,
            col_ptr,
            col_idx,
            col_w,
        })
    }

    /// `A x = b` on the active cells (0 elsewhere), `b` and `x` indexed by grid cell.
    pub fn solve(&self, b: &[f64], x: &mut [f64]) {
        let m = self.cells.len();
        let mut y: Vec<f64> = self.cells.iter().map(|&k| b[k]).collect();
        for p in 0..m {
            let yp = y[p];
            if yp != 0.0 {
                for t in self.col_ptr[p]..self.col_ptr[p + 1] {
                    y[self.col_idx[t] as usize] += self.col_w[t] * yp;
                }
            }
        }
        y.iter_mut().zip(&self.pivot).for_each(|(v, d)| *v /= d);
        for p in (0..m).rev() {
            let mut v = y[p];
            for t in self.col_ptr[p]..self.col_ptr[p + 1] {
                v += self.col_w[t] * y[self.col_idx[t] as usize];
            }
            y[p] = v;
        }
        x.iter_mut().for_each(|v| *v = 0.0);
        for (p, &k) in self.cells.iter().enumerate() {
            x[k] = y[p];
        }
    }
}
