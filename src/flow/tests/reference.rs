//! The solvers against a dense Cholesky factor of the same system assembled cell by cell,
//! and the same bits on one and two threads.
#![allow(clippy::needless_range_loop)]
use super::*;
use faer::prelude::Solve;
use faer::{Mat, Side};

/// Dense reference: the same finite-volume system assembled cell by cell and solved with a
/// dense Cholesky factor (faer).
fn dense_reference(
    gap: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
    eta: f64,
    dp: f64,
) -> (Vec<f64>, f64) {
    let n = ny * nx;
    let c: Vec<f64> = gap.iter().map(|g| g.powi(3) / (12.0 * eta)).collect();
    // Spanning cells by flood fill from the inlet, then from the outlet.
    let flood = |seeds: Vec<usize>| {
        let mut seen = vec![false; n];
        let mut stack = seeds;
        while let Some(k) = stack.pop() {
            if seen[k] || c[k] <= 0.0 {
                continue;
            }
            seen[k] = true;
            stack.extend(grid_neighbours(k, ny, nx, periodic));
        }
        seen
    };
    let from_in = flood((0..nx).collect());
    let from_out = flood(((ny - 1) * nx..n).collect());
    let idx: Vec<usize> = (0..n).filter(|&k| from_in[k] && from_out[k]).collect();
    let mut pos = vec![usize::MAX; n];
    for (m, &k) in idx.iter().enumerate() {
        pos[k] = m;
    }
    let m = idx.len();
    let mut a = Mat::<f64>::zeros(m, m);
    let mut b = Mat::<f64>::zeros(m, 1);
    let h = |c1: f64, c2: f64| {
        if c1 > 0.0 && c2 > 0.0 {
            2.0 * c1 * c2 / (c1 + c2)
        } else {
            0.0
        }
    };
    for (r, &k) in idx.iter().enumerate() {
        let i = k / nx;
        for q in grid_neighbours(k, ny, nx, periodic) {
            let cf = h(c[k], c[q]);
            if cf > 0.0 {
                a[(r, r)] += cf;
                a[(r, pos[q])] -= cf;
            }
        }
        if i == 0 {
            a[(r, r)] += 2.0 * c[k];
            b[(r, 0)] += 2.0 * c[k] * dp;
        }
        if i + 1 == ny {
            a[(r, r)] += 2.0 * c[k];
        }
    }
    let mut p = vec![f64::NAN; n];
    let mut q = 0.0;
    if m > 0 {
        let x = a.llt(Side::Lower).unwrap().solve(&b);
        for (r, &k) in idx.iter().enumerate() {
            p[k] = x[(r, 0)];
            if k / nx == ny - 1 {
                q += 2.0 * c[k] * x[(r, 0)];
            }
        }
    }
    (p, q)
}

/// Rates and pressures against the dense reference, `solver` forced.
fn matches_dense_cholesky_reference_with(solver: Solver) {
    for (seed, ny, nx, periodic, closed) in [
        (1, 30, 41, false, 0.3),
        (2, 45, 45, true, 0.35),
        (4, 70, 20, false, 0.2),
        (6, 3, 90, true, 0.4),
    ] {
        let gap = random_gap(seed, ny * nx, closed);
        let pr = problem(&gap, ny, nx, 0, periodic);
        let sol = solve(&pr, &forced(solver)).unwrap();
        let (p, q) = dense_reference(&gap, ny, nx, periodic, pr.viscosity, pr.pressure_drop);
        if q == 0.0 {
            assert_eq!(sol.flow_rate, 0.0);
            continue;
        }
        assert!(rel(sol.flow_rate, q) < 1e-10, "{} vs {q}", sol.flow_rate);
        for k in 0..ny * nx {
            if !p[k].is_nan() {
                assert!((sol.pressure[k] - p[k]).abs() < 1e-10 * pr.pressure_drop);
            }
        }
    }
}

#[test]
fn matches_dense_cholesky_reference() {
    matches_dense_cholesky_reference_with(Solver::Auto);
}

#[test]
fn matches_dense_cholesky_reference_multigrid() {
    matches_dense_cholesky_reference_with(Solver::Multigrid);
}

/// The same bits on one and two threads, `solver` forced.
fn same_bits_on_one_and_two_threads_with(solver: Solver) {
    let (ny, nx) = (300, 260);
    let gap = random_gap(11, ny * nx, 0.3);
    let run = |t: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        pool.install(|| solve(&problem(&gap, ny, nx, 0, true), &forced(solver)).unwrap())
    };
    let (a, b) = (run(1), run(2));
    assert_eq!(a.flow_rate.to_bits(), b.flow_rate.to_bits());
    assert_eq!(a.iterations, b.iterations);
    assert!(a
        .pressure
        .iter()
        .zip(&b.pressure)
        .all(|(x, y)| x.to_bits() == y.to_bits()));
}

#[test]
fn same_bits_on_one_and_two_threads() {
    same_bits_on_one_and_two_threads_with(Solver::Auto);
}

#[test]
fn same_bits_on_one_and_two_threads_multigrid() {
    same_bits_on_one_and_two_threads_with(Solver::Multigrid);
}
