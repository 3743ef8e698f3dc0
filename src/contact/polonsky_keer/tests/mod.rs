//! Tests of the Polonsky–Keer solver against independent references, one file a concern;
//! the shared problems and the dense reference are here.

use super::driver::height_stats;
use super::sparse::add_sparse;
use super::*;
use crate::contact::kkt::kkt_certificate;
use crate::elastic::kernel::love_displacement;
use crate::elastic::operator::dense_apply;
use std::f64::consts::PI;

use crate::test_support::lcg;

mod arithmetic;
mod inputs;
mod reference;
mod variants;

/// A rough-ish random surface: white noise smoothed by a 3×3 (periodic) box filter.
fn rough(ny: usize, nx: usize, seed: u64) -> Vec<f64> {
    let w = lcg(seed, ny * nx);
    let mut h = vec![0.0; ny * nx];
    for i in 0..ny {
        for j in 0..nx {
            let mut s = 0.0;
            for di in [ny - 1, 0, 1] {
                for dj in [nx - 1, 0, 1] {
                    s += w[((i + di) % ny) * nx + (j + dj) % nx];
                }
            }
            h[i * nx + j] = s / 9.0;
        }
    }
    h
}

fn problem(h: &[f64], ny: usize, nx: usize, boundary: Boundary) -> Problem<'_> {
    Problem {
        heights: h,
        ny,
        nx,
        dx: 0.7,
        e_star: 1.3,
        boundary,
    }
}

fn opts(tol: f64) -> Options<'static> {
    Options {
        tol,
        ..Options::default()
    }
}

/// Dense `C` (row-major `n × n`) by applying the operator to unit vectors.
fn dense_matrix_from_operator(op: &Operator) -> Vec<f64> {
    let n = op.ny * op.nx;
    let mut c = vec![0.0; n * n];
    let mut e = vec![0.0; n];
    let mut col = vec![0.0; n];
    for j in 0..n {
        e[j] = 1.0;
        op.apply(&e, &mut col);
        e[j] = 0.0;
        for i in 0..n {
            c[i * n + j] = col[i];
        }
    }
    c
}

/// Exact solution of `min ½pᵀCp − bᵀp, p ≥ 0` for a small dense SPD `C`: projected
/// Gauss–Seidel to find the active set, then a Cholesky solve on it, repeated until KKT
/// holds to round-off.
fn dense_reference(c: &[f64], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut p = vec![0.0; n];
    for _round in 0..200 {
        for _ in 0..2000 {
            for i in 0..n {
                let gi: f64 = (0..n).map(|j| c[i * n + j] * p[j]).sum::<f64>() - b[i];
                p[i] = (p[i] - gi / c[i * n + i]).max(0.0);
            }
        }
        let act: Vec<usize> = (0..n).filter(|&i| p[i] > 0.0).collect();
        let k = act.len();
        // Cholesky of C_PP.
        let mut l = vec![0.0; k * k];
        for a in 0..k {
            for bb in 0..=a {
                let mut s = c[act[a] * n + act[bb]];
                for m in 0..bb {
                    s -= l[a * k + m] * l[bb * k + m];
                }
                if a == bb {
                    l[a * k + a] = s.sqrt();
                } else {
                    l[a * k + bb] = s / l[bb * k + bb];
                }
            }
        }
        let mut z: Vec<f64> = act.iter().map(|&i| b[i]).collect();
        for a in 0..k {
            for m in 0..a {
                z[a] -= l[a * k + m] * z[m];
            }
            z[a] /= l[a * k + a];
        }
        for a in (0..k).rev() {
            for m in a + 1..k {
                z[a] -= l[m * k + a] * z[m];
            }
            z[a] /= l[a * k + a];
        }
        let mut q = vec![0.0; n];
        for (a, &i) in act.iter().enumerate() {
            q[i] = z[a];
        }
        let g: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| c[i * n + j] * q[j]).sum::<f64>() - b[i])
            .collect();
        let bs = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
        if q.iter().all(|&v| v >= 0.0) && g.iter().all(|&v| v >= -1e-13 * bs) {
            return q;
        }
    }
    panic!("dense reference did not converge");
}

/// The largest approach of a solve: `max h − min h` on a free surface, `max h − mean h`
/// (full contact) on a periodic one.
fn approach_range(h: &[f64], boundary: Boundary) -> f64 {
    let (hmax, hmin, hsum) = height_stats(h);
    match boundary {
        Boundary::Free => hmax - hmin,
        Boundary::Periodic => hmax - hsum / h.len() as f64,
    }
}

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let s = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / s
}

/// `a` (with `f32` products) and `b` (in `f64` throughout) solve the same problem: both
/// certificates below `tol`, the same contact set, `a`'s gap the `f64` gap of its pressure
/// (recomputed with `op`) whose certificate is below `2 tol`, gaps on the contact set, the
/// load and the approach within the certificates' bound.
#[allow(clippy::too_many_arguments)]
fn assert_same_minimiser(
    op: &Operator,
    h: &[f64],
    hmax: f64,
    hs: f64,
    a: &Solution,
    b: &Solution,
    tol: f64,
    what: &str,
) {
    assert!(a.kkt <= tol && b.kkt <= tol, "{what}");
    let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
    let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
    assert_eq!(ca, cb, "{what}");
    // The gap of the returned pressure, in f64.
    let mut u = vec![0.0; h.len()];
    op.apply(&a.pressure, &mut u);
    let g: Vec<f64> = (0..h.len())
        .map(|i| hmax - a.approach - h[i] + u[i])
        .collect();
    let scale = hs.max(a.approach);
    for (x, y) in g.iter().zip(&a.gap) {
        assert!((x - y).abs() <= 1e-12 * scale, "{what}");
    }
    assert!(
        kkt_certificate(&a.pressure, &g, scale) <= 2.0 * tol,
        "{what}"
    );
    let bound = (a.kkt + b.kkt) * scale;
    let dg = a
        .gap
        .iter()
        .zip(&b.gap)
        .zip(&a.pressure)
        .filter(|&(_, &p)| p > 0.0)
        .fold(0.0f64, |m, ((x, y), _)| m.max((x - y).abs()));
    assert!(dg <= bound, "{what}: {dg} vs {bound}");
    let dl = (a.load - b.load).abs() / b.load;
    assert!(dl <= 1e-6, "{what}: load rel diff {dl}");
    assert!((a.approach - b.approach).abs() <= 1e3 * bound, "{what}");
}
