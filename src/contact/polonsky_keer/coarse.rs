//! Coarse-to-fine start for Polonsky–Keer: solve the contact problem on the grid coarsened by
//! two (every other node, spacing `2 dx`, recursively while a grid has at least
//! [`COARSE_START_MIN_SIDE`] points per side, at most [`MAX_COARSE_LEVELS`] levels), prolong
//! its pressure to the fine grid, and start the fine iteration from it.
//!
//! # Restriction and prolongation
//!
//! The coarse grid keeps the nodes `(2i, 2j)` of the fine one: `ny_c = ⌈ny/2⌉`, so a
//! `(2^k + 1)²` grid covers the same patch at every level. Heights are sampled at those nodes
//! (a 2×2 average would lower every summit, and the contact spots are the summits). The
//! pressure is a force per area, so it is transferred without scaling: bilinear on the node
//! grid, `p(2i+1, j) = ½ (p_c(i) + p_c(i+1))` along each axis (the last row/column of an
//! even-sized grid repeats its neighbour).
//!
//! # Control on the coarse grid
//!
//! * displacement: the flat stays at the same height `max h − Δ`; the coarse surface's highest
//!   node may be lower than the fine one, so the coarse approach is `Δ − (max h − max h_c)`
//!   (nothing touches if that is ≤ 0: no start is made).
//! * load: the same mean pressure.
//!
//! The coarse solve stops at [`COARSE_TOL`]: its discretisation error (the spots are resolved
//! with half the nodes) dominates what the fine solve has to correct, so a tighter coarse
//! solve buys nothing (measured, see [`COARSE_TOL`]). Only the coarse pressure is used, so a
//! coarse level stops on its incrementally updated state, without the confirming product a
//! solve returned to a caller ends with.
//!
//! # What a better start is worth
//!
//! Little, measured at 1025² and 2049² (RMD D = 2.2, free, tol 1e-8, `Δ` in units of the
//! height range; `benchmarks/results/contact_scale.md`). At 2049², `Δ = 0.3 h_s` the coarse
//! level ends with 35,551 contact points (1.3× its converged set), the prolongation spreads
//! them to 176,143 fine points, the answer has 93,725; the solve takes 92.9 products.
//! Started instead from the answer itself with 10 % too much pressure (the exact contact set)
//! it takes 88: the first preconditioned steps truncate and re-add 5–10 % of the set (most
//! points of a fractal contact set lie near a boundary), which sets off chord steps, and the
//! settled set then converges at about 8 conjugate iterations per decade. Tried at 1025²
//! (`Δ` = 0.1/0.3/0.6 h_s, default 34.4/66.9/89.5 products) and not kept: zeroing the
//! prolonged pressure where the fine gap of one product `C p₀` is open (44.2/79.7/96.0; with
//! `Σ p` kept 40.7/63.7/100.3), a projected Jacobi step `p ← max(0, p − ½ g/C_00)` after the
//! prolongation (34.9/91.4/125.8), coarse tolerance 1e-3 (33.4/77.0/98.5), coarse heights as
//! the maximum (42.6/66.1/105.4) or mean (34.3/73.3/101.8) of the 3×3 fine block, a smaller
//! coarse approach (0.85 Δ: 37.1/78.1/125.3).
//!
//! # Cost
//!
//! A free level's Love table is not evaluated afresh: the kernel is homogeneous of degree one,
//! so it is the finer table's leading block times two, bit for bit
//! ([`crate::elastic::kernel::try_coarsened_table`]), when the finer level has its table
//! (every solve through [`super::solve_with_kernel`], the bindings' path, and the capped solver's
//! levels).
//!
//! A product on the coarse grid costs about a quarter of a fine one; the levels together cost
//! about a third of the coarsest-to-finest products taken at the fine size. The fine solve's
//! [`Solution`] reports the coarse levels' raw counts and their fine-grid equivalents
//! (`Σ products · N_level / N`) separately.

use rayon::prelude::*;

use crate::contact::problem::{CoarseCost, Control, Options, Problem, Solution};
use crate::error::Result;
use crate::grid::Boundary;

/// Grids with fewer points than this per side (the smaller side) start cold: below it the
/// coarse solve and the prolongation cost about as much as they save. On grids below
/// `4 ×` this per side the coarsest level solved has between half of this and this many
/// points per side; larger grids stop after [`MAX_COARSE_LEVELS`] levels.
pub const COARSE_START_MIN_SIDE: usize = 64;

/// KKT tolerance of the coarse solves (relative to the coarse height range). Measured on
/// spectral surfaces (H = 0.9, free, Δ = 0.3 and 0.6 h_s, fine tolerance 1e-8) at 513² and
/// 1025²: coarse tolerances from 1e-2 to 1e-6 leave the fine iterations within ±10 % of each
/// other, and 1e-2 takes the fewest coarse products. Other prolongations measured at 513²
/// (zeroing the pressure where the interpolated gap is open, adding a Winkler pressure where it
/// overlaps, keeping only points with all four coarse neighbours in contact) took 10–20 % more
/// fine iterations than the plain bilinear one.
pub const COARSE_TOL: f64 = 1e-2;

/// At most this many coarse levels below the grid solved; the coarsest of them starts from
/// `p = 0`. Every level costs at least one product for its start and a few iterations, so
/// deep hierarchies add products on small grids that save nothing on the fine one. Measured
/// (spectral H = 0.9, free, Δ = 0.1/0.3/0.6 h_s, tolerance 1e-8), fine + coarse products
/// counted raw, with 1, 2, 3, 4 and all 5 levels at 1025²: 43/85/123, 41/85/118, 46/91/126,
/// 48/99/141, 51/99/150; at the fine-grid equivalent (coarse products at their share of the
/// points): 36.3/66.3/98.3, 30.7/60.8/86.7, 33.6/64.5/87.3, 32.6/67.4/95.3, 32.6/64.4/96.3.
/// At 4097² (RMD D = 2.1), raw: 2 levels 90/248/399; 3 levels 98 (Δ = 0.1 h_s) and 249
/// (0.3 h_s); all six levels, before the coarse levels dropped their confirming product and
/// the influence-table product, 102/282/428.
pub const MAX_COARSE_LEVELS: usize = 2;

/// Whether a coarse start is made for a grid (the option is on, there is no warm start, and
/// the grid is large enough).
pub fn applies_to(ny: usize, nx: usize, opts: &Options, initial: Option<&[f64]>) -> bool {
    opts.coarse_start && initial.is_none() && ny.min(nx) >= COARSE_START_MIN_SIDE
}

/// Coarse grid size along one axis.
pub fn coarse_side(n: usize) -> usize {
    n.div_ceil(2)
}

/// The coarse-level start pressure for `problem` (fine grid), with the cost of all coarser
/// levels, or `None` when the coarse solve has nothing in contact. `solve_coarse(problem,
/// control, options, levels)` solves a coarse level (with at most `levels` below it) and may
/// stop on its incrementally updated state: only its pressure is used.
pub fn start(
    problem: &Problem,
    control: Control,
    opts: &Options,
    levels: usize,
    solve_coarse: impl Fn(&Problem, Control, &Options, usize) -> Result<Solution>,
) -> Result<Option<(Vec<f64>, CoarseCost)>> {
    let (ny, nx) = (problem.ny, problem.nx);
    let (cy, cx) = (coarse_side(ny), coarse_side(nx));
    let h = problem.heights;
    let mut hc = crate::alloc::try_with_capacity(cy * cx, "the coarse heights")?;
    for i in 0..cy {
        let row = &h[2 * i * nx..(2 * i + 1) * nx];
        hc.extend(row.iter().step_by(2).copied());
    }
    let hmax = h.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let hmax_c = hc.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let coarse_control = match control {
        Control::Approach(d) => {
            let dc = d - (hmax - hmax_c);
            if dc <= 0.0 {
                return Ok(None);
            }
            if problem.boundary == Boundary::Periodic {
                // Stay below the coarse grid's full-contact approach (max h_c − mean h_c).
                let mean = hc.iter().sum::<f64>() / hc.len() as f64;
                Control::Approach(dc.min(hmax_c - mean))
            } else {
                Control::Approach(dc)
            }
        }
        c @ Control::MeanPressure(_) => c,
    };
    let coarse = Problem {
        heights: &hc,
        ny: cy,
        nx: cx,
        dx: 2.0 * problem.dx,
        e_star: problem.e_star,
        boundary: problem.boundary,
    };
    let copts = Options {
        tol: COARSE_TOL.max(opts.tol),
        max_iter: None,
        memory_limit: None,
        should_stop: opts.should_stop,
        precondition: opts.precondition,
        coarse_start: true,
        chord_steps: opts.chord_steps,
        rescaled_steps: opts.rescaled_steps,
        hardness: opts.hardness,
        single_precision_above: opts.single_precision_above,
    };
    // Only the coarse pressure is used: no confirming product at the end of a coarse level.
    let sol = solve_coarse(&coarse, coarse_control, &copts, levels - 1)?;
    drop(hc);
    if sol.contact_points == 0 {
        return Ok(None);
    }
    let ratio = (cy * cx) as f64 / (ny * nx) as f64;
    let below = sol.coarse;
    let cost = CoarseCost {
        levels: below.levels + 1,
        iterations: below.iterations + sol.iterations,
        fft_products: below.fft_products + sol.fft_products,
        preconditioner_products: below.preconditioner_products + sol.preconditioner_products,
        fft_products_fine_equivalent: ratio
            * (sol.fft_products as f64 + below.fft_products_fine_equivalent),
        preconditioner_products_fine_equivalent: ratio
            * (sol.preconditioner_products as f64 + below.preconditioner_products_fine_equivalent),
    };
    let p = prolong(&sol.pressure, cy, cx, ny, nx)?;
    Ok(Some((p, cost)))
}

/// Bilinear prolongation of a node field from `cy × cx` to `ny × nx` (`cy = ⌈ny/2⌉`).
pub fn prolong(pc: &[f64], cy: usize, cx: usize, ny: usize, nx: usize) -> Result<Vec<f64>> {
    let mut p = crate::alloc::try_zeroed(ny * nx, "the coarse-start pressure")?;
    // Coarse neighbours of a fine index along one axis.
    let pair = |k: usize, nc: usize| -> (usize, usize) {
        let a = k / 2;
        if k % 2 == 0 {
            (a, a)
        } else {
            (a, (a + 1).min(nc - 1))
        }
    };
    p.par_chunks_mut(nx).enumerate().for_each(|(i, out)| {
        let (i0, i1) = pair(i, cy);
        let (r0, r1) = (&pc[i0 * cx..(i0 + 1) * cx], &pc[i1 * cx..(i1 + 1) * cx]);
        for (j, v) in out.iter_mut().enumerate() {
            let (j0, j1) = pair(j, cx);
            *v = 0.25 * (r0[j0] + r0[j1] + r1[j0] + r1[j1]);
        }
    });
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prolongation_is_exact_for_bilinear_fields() {
        // Odd sides: the coarse nodes cover the fine patch; a field a + b i + c j + d i j
        // (fine indices) is reproduced at every fine node.
        let f = |i: f64, j: f64| 0.5 + 0.25 * i - 0.125 * j + 0.01 * i * j;
        for &(ny, nx) in &[(9usize, 13usize), (1, 7), (5, 1)] {
            let (cy, cx) = (coarse_side(ny), coarse_side(nx));
            let pc: Vec<f64> = (0..cy * cx)
                .map(|k| f(2.0 * (k / cx) as f64, 2.0 * (k % cx) as f64))
                .collect();
            let p = prolong(&pc, cy, cx, ny, nx).unwrap();
            for i in 0..ny {
                for j in 0..nx {
                    let want = f(i as f64, j as f64);
                    assert!((p[i * nx + j] - want).abs() < 1e-14, "({i}, {j})");
                }
            }
        }
        // Even sides: the last row and column repeat their coarse neighbour.
        let (ny, nx) = (4usize, 6usize);
        let pc: Vec<f64> = (0..2 * 3).map(|k| k as f64).collect();
        let p = prolong(&pc, 2, 3, ny, nx).unwrap();
        assert_eq!(p[3 * nx + 5], pc[5]);
        assert_eq!(p[5], pc[2]);
        assert_eq!(p[nx + 1], 0.25 * (pc[0] + pc[1] + pc[3] + pc[4]));
    }
}
