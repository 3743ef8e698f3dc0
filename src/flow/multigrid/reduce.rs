//! Exact elimination of half the finest level: the red cells of a checkerboard.
//!
//! On the five-point stencil a cell's faces join it only to cells of the other colour of a
//! checkerboard, so the red unknowns (row + column even) are mutually independent and
//! eliminate exactly. Ordering them first,
//!
//! ```text
//! A = [ D_R    −W_RB ]  = L [ D_R  0 ] Lᵀ,   L = [ I              0 ],
//!     [ −W_BR   A_BB ]      [ 0    S ]           [ −W_BR D_R⁻¹    I ]
//! S = A_BB − W_BR D_R⁻¹ W_RB,
//! ```
//!
//! with `D_R` diagonal. The preconditioner is `A⁻¹` with `S⁻¹` replaced by one multigrid
//! cycle on `S` (`M_S`), `B = L⁻ᵀ diag(D_R⁻¹, M_S) L⁻¹`: symmetric positive definite
//! whenever `M_S` is, and `κ(B A) = κ(M_S S)`. Applied to `r`:
//!
//! ```text
//! s_B = r_B + W_BR D_R⁻¹ r_R,   z_B = M_S s_B,   z_R = D_R⁻¹ (r_R + W_RB z_B),
//! ```
//!
//! two passes with no dependence from row to row, in place of the Gauss–Seidel sweeps,
//! residual and transfers of a classical first coarse level; and `S` is formed from the
//! stencil directly instead of by a splitting, an interpolation and a Galerkin product.
//! `S` is again an M-matrix in conductance form: the black unknowns `i`, `j` two cells apart
//! are joined by `Σ_r w_ir w_rj / d_r` over their common red neighbours `r`, and the
//! reservoir part of row `i` is `dir_i + Σ_r w_ir dir_r / d_r` (a sum of positive terms:
//! the row sum of `S`, without cancellation). Its faces are stored in single precision like
//! every coarse level's; the residuals stay those of the exact fine operator.
//!
//! A wrapped grid with an odd number of columns joins column `nx − 1` to column 0, both of
//! the same parity: its last column is kept whole (black), so the red cells stay independent.

use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use super::cycle::Fine;
use super::{concat, Graph, RowBlock, CHUNK, NONE};

/// Kept unknowns per block of [`Reduction::schur_product`] (some 27 grid rows at 4097²,
/// so that recomputing the red cells of the rows around a block costs a few per cent).
pub(super) const PRODUCT_BLOCK: usize = 4 * CHUNK;

/// The tag of a red unknown's [`Reduction::slot`] (fine unknowns number below 2^31).
const RED: u32 = 1 << 31;

/// The red (eliminated) and black (kept) fine unknowns.
pub(super) struct Reduction {
    /// Fine unknown of each kept unknown, ascending.
    pub(super) kept: Vec<u32>,
    /// Fine unknown of each red unknown, ascending.
    reds: Vec<u32>,
    /// Of each fine unknown: its kept index, or [`RED`] with its red index.
    pub(super) slot: Vec<u32>,
    /// Of each grid cell: its unknown's `slot` ([`NONE`] without an unknown), so that
    /// [`Reduction::schur_product`] reaches a neighbour's entry in one lookup, not two.
    cell_slot: Vec<u32>,
    /// Whether every face of the stored `S` is a normal single-precision number (none
    /// dropped or subnormal), set by [`Reduction::schur`].
    faithful: bool,
}

/// Whether grid cell `k` of a `· × nx` grid is red.
#[inline(always)]
fn red(k: usize, nx: usize, periodic: bool) -> bool {
    let (row, col) = (k / nx, k % nx);
    (row + col) % 2 == 0 && !(periodic && nx % 2 == 1 && col == nx - 1)
}

impl Reduction {
    /// The checkerboard of the finest level's unknowns.
    pub(super) fn new(top: &Fine<'_>) -> Self {
        let (nx, periodic) = (top.st.nx, top.st.periodic);
        let is_red: Vec<bool> = top
            .cells
            .par_iter()
            .with_min_len(CHUNK)
            .map(|&k| red(k as usize, nx, periodic))
            .collect();
        assert!(is_red.len() < RED as usize, "fine unknowns below 2^31");
        let mut slot = vec![NONE; is_red.len()];
        let mut kept = Vec::with_capacity(is_red.len() / 2 + 1);
        let mut reds = Vec::with_capacity(is_red.len() / 2 + 1);
        for (i, &r) in is_red.iter().enumerate() {
            if r {
                slot[i] = RED | reds.len() as u32;
                reds.push(i as u32);
            } else {
                slot[i] = kept.len() as u32;
                kept.push(i as u32);
            }
        }
        let cell_slot = top
            .index
            .par_iter()
            .with_min_len(CHUNK)
            .map(|&j| if j == NONE { NONE } else { slot[j as usize] })
            .collect();
        Reduction {
            kept,
            reds,
            slot,
            cell_slot,
            faithful: false,
        }
    }

    /// Whether fine unknown `i` is red.
    #[inline(always)]
    pub(super) fn is_red(&self, i: usize) -> bool {
        self.slot[i] & RED != 0
    }

    /// Kept unknowns (the size of `S`).
    pub(super) fn len(&self) -> usize {
        self.kept.len()
    }

    /// Bytes held.
    pub(super) fn bytes(&self) -> usize {
        4 * (self.kept.len() + self.reds.len() + self.slot.len() + self.cell_slot.len())
    }

    /// The Schur complement `S` on the kept unknowns, in conductance form (module docs).
    pub(super) fn schur(&mut self, top: &Fine<'_>) -> Graph {
        let ns = self.kept.len();
        // Cleared by any face that single precision stores coarsely (subnormal) or not at all.
        let faithful = AtomicBool::new(true);
        let blocks: Vec<RowBlock> = (0..ns.div_ceil(CHUNK))
            .into_par_iter()
            .map(|blk| {
                let rows = blk * CHUNK..((blk + 1) * CHUNK).min(ns);
                let mut len = Vec::with_capacity(rows.len());
                let mut col = Vec::new();
                let mut w = Vec::new();
                let mut dir = Vec::with_capacity(rows.len());
                let mut acc: Vec<(u32, f64)> = Vec::with_capacity(16);
                for s in rows {
                    let i = self.kept[s] as usize;
                    acc.clear();
                    // Entries in the order first reached (fixed by the grid), summed there.
                    let add = |acc: &mut Vec<(u32, f64)>, c: u32, v: f64| match acc
                        .iter_mut()
                        .find(|e| e.0 == c)
                    {
                        Some(e) => e.1 += v,
                        None => acc.push((c, v)),
                    };
                    let k = top.cells[i] as usize;
                    let mut res = top.st.dir[k];
                    // The stencil's faces directly (a 2-wide wrapped row's two faces to the
                    // same neighbour come one by one; their sum is the same face).
                    top.st.for_each_face(k, |l, wij| {
                        let j = top.index[l];
                        if j == NONE {
                            return;
                        }
                        let sj = self.slot[j as usize];
                        if sj & RED == 0 {
                            add(&mut acc, sj, wij);
                            return;
                        }
                        let dj = top.st.d[l];
                        res += wij * top.st.dir[l] / dj;
                        top.st.for_each_face(l, |q, wjm| {
                            let m = top.index[q];
                            if m != NONE && m as usize != i {
                                add(&mut acc, self.slot[m as usize], wij * wjm / dj);
                            }
                        });
                    });
                    if acc.iter().any(|e| !(e.1 as f32).is_normal()) {
                        faithful.store(false, Ordering::Relaxed);
                    }
                    // Stored in single precision: a face that rounds to 0 is dropped.
                    acc.retain(|e| e.1 as f32 != 0.0);
                    acc.sort_unstable_by_key(|e| e.0);
                    len.push(acc.len());
                    for &(c, v) in acc.iter() {
                        col.push(c);
                        w.push(v as f32);
                    }
                    dir.push(res);
                }
                (len, col, w, dir)
            })
            .collect();
        let (ptr, col, w, dir) = concat(blocks);
        self.faithful = faithful.into_inner();
        Graph::from_faces(ptr, col, w, dir)
    }

    /// Whether every face of the stored `S` is a normal single-precision number, so within
    /// 2^-24 of the exact face ([`Reduction::schur`]).
    pub(super) fn faithful(&self) -> bool {
        self.faithful
    }

    /// `s = r_B + W_BR D_R⁻¹ r_R` on the kept unknowns.
    pub(super) fn restrict(&self, top: &Fine<'_>, r: &[f64], s: &mut [f64]) {
        s.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, sc)| {
            for (t, o) in sc.iter_mut().enumerate() {
                let i = self.kept[blk * CHUNK + t] as usize;
                let mut v = r[i];
                top.st.for_each_face(top.cells[i] as usize, |l, c| {
                    let j = top.index[l];
                    if j != NONE && self.is_red(j as usize) {
                        v += c * r[j as usize] / top.st.d[l];
                    }
                });
                *o = v;
            }
        });
    }

    /// `y = S v = A_BB v − W_BR D_R⁻¹ W_RB v` on the kept unknowns, from the stencil in
    /// double precision (not from the stored single-precision `S`). In blocks of
    /// [`PRODUCT_BLOCK`] kept unknowns, in one pass over the grid: walking the block's rows,
    /// `u_r = (W_RB v)_r / d_r` of the red unknowns up to one grid row ahead, then the kept
    /// rows, which read `u` of their red neighbours from the block's buffer (recently
    /// computed, so in cache). Each block computes the red unknowns of the grid row before
    /// and after it again. Every entry is the same sum whatever the blocks.
    pub(super) fn schur_product(&self, top: &Fine<'_>, v: &[f64], y: &mut [f64]) {
        let nx = top.st.nx;
        let last = top.st.ny * nx - 1;
        // What the unchecked loads below rely on: the stencil's faces and diagonal cover the
        // grid, a slot per cell, and vectors with an entry per kept unknown (every kept slot
        // is below `kept.len()` by construction, every cell of an unknown below the grid's
        // size), which spares the loop a compare and a branch per face.
        assert!(
            top.st.faces_complete()
                && top.st.d.len() == last + 1
                && self.cell_slot.len() == last + 1
                && v.len() == self.kept.len()
                && y.len() == self.kept.len(),
            "the Schur product's stencil, slots and vectors cover the grid"
        );
        let cell_of = |i: u32| top.cells[i as usize] as usize;
        // The slot of neighbour `l` of a cell (`l` below the grid's size).
        // SAFETY: `cell_slot` has one entry per cell (checked above).
        let slot_of = |l: usize| unsafe { *self.cell_slot.get_unchecked(l) };
        // SAFETY: a kept slot is below `kept.len() = v.len()` (checked above).
        let v_at = |sj: u32| unsafe { *v.get_unchecked(sj as usize) };
        y.par_chunks_mut(PRODUCT_BLOCK)
            .enumerate()
            .for_each_init(Vec::new, |u, (blk, yc)| {
                let s0 = blk * PRODUCT_BLOCK;
                // The red unknowns whose cells lie from a grid row before the block's first
                // cell to a row after its last: all the red neighbours of its rows.
                let (ka, kb) = (
                    cell_of(self.kept[s0]),
                    cell_of(self.kept[s0 + yc.len() - 1]),
                );
                let r_lo = self
                    .reds
                    .partition_point(|&i| cell_of(i) < ka.saturating_sub(nx));
                let r_hi = self
                    .reds
                    .partition_point(|&i| cell_of(i) <= (kb + nx).min(last));
                u.clear();
                u.resize(r_hi - r_lo, 0.0);
                let mut r = r_lo;
                for (t, o) in yc.iter_mut().enumerate() {
                    let s = s0 + t;
                    let k = cell_of(self.kept[s]);
                    // Red unknowns up to a row ahead (the south face and a wrapped east face
                    // reach at most `k + nx`).
                    let ahead = (k + nx).min(last);
                    while r < r_hi && cell_of(self.reds[r]) <= ahead {
                        let kr = cell_of(self.reds[r]);
                        let mut a = 0.0;
                        // Every neighbour of a red unknown is kept.
                        // SAFETY: the faces cover the grid (checked above) and `kr` is a cell.
                        unsafe {
                            top.st.for_each_face_unchecked(kr, |l, c| {
                                let sj = slot_of(l);
                                debug_assert!(sj == NONE || sj & RED == 0, "red cells adjacent");
                                if sj != NONE {
                                    a += c * v_at(sj);
                                }
                            });
                        }
                        u[r - r_lo] = a / top.st.d[kr];
                        r += 1;
                    }
                    let mut a = 0.0;
                    // SAFETY: as above, `k` is a cell.
                    unsafe {
                        top.st.for_each_face_unchecked(k, |l, c| {
                            let sj = slot_of(l);
                            if sj == NONE {
                                return;
                            }
                            // A kept neighbour: the wrapped odd column's faces (A_BB).
                            a += c * if sj & RED == 0 {
                                v_at(sj)
                            } else {
                                u[(sj & !RED) as usize - r_lo]
                            };
                        });
                    }
                    *o = top.st.d[k] * v[s] - a;
                }
            });
    }

    /// `z_B = z_s`, `z_R = D_R⁻¹ (r_R + W_RB z_s)` on the fine unknowns.
    pub(super) fn extend(&self, top: &Fine<'_>, r: &[f64], zs: &[f64], z: &mut [f64]) {
        z.par_chunks_mut(CHUNK).enumerate().for_each(|(blk, zc)| {
            for (t, o) in zc.iter_mut().enumerate() {
                let i = blk * CHUNK + t;
                let s = self.slot[i];
                if s & RED == 0 {
                    *o = zs[s as usize];
                    continue;
                }
                let k = top.cells[i] as usize;
                let mut v = r[i];
                // Every neighbour of a red unknown is kept.
                top.st.for_each_face(k, |l, c| {
                    let j = top.index[l];
                    if j != NONE {
                        v += c * zs[self.slot[j as usize] as usize];
                    }
                });
                *o = v / top.st.d[k];
            }
        });
    }
}
