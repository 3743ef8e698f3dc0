#![allow(clippy::needless_range_loop)]
use super::*;
use faer::prelude::Solve;
use faer::{Mat, Side};

/// [`crate::test_support::lcg`] from `seed` advanced once (the flow tests' inputs).
pub(super) fn lcg(seed: u64, n: usize) -> Vec<f64> {
    let (a, c) = crate::test_support::LCG;
    crate::test_support::lcg(seed.wrapping_mul(a).wrapping_add(c), n)
}

fn problem<'a>(gap: &'a [f64], ny: usize, nx: usize, axis: usize, periodic: bool) -> Problem<'a> {
    Problem {
        gap,
        contact: None,
        ny,
        nx,
        dx: 0.5,
        axis,
        viscosity: 2.0,
        pressure_drop: 3.0,
        periodic,
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// Random gaps with about `closed` of the cells in contact (gap 0).
fn random_gap(seed: u64, n: usize, closed: f64) -> Vec<f64> {
    let u = lcg(seed, 2 * n);
    (0..n)
        .map(|k| if u[n + k] < closed { 0.0 } else { 0.05 + u[k] })
        .collect()
}

#[test]
fn parallel_plates_exact() {
    for &(ny, nx, periodic) in &[
        (1, 1, false),
        (7, 5, false),
        (40, 33, true),
        (65, 300, false),
    ] {
        for axis in 0..2 {
            let g = 0.37;
            let gap = vec![g; ny * nx];
            let pr = problem(&gap, ny, nx, axis, periodic);
            let sol = solve(&pr, &Options::default()).unwrap();
            let (w, l) = if axis == 0 {
                (nx as f64 * pr.dx, ny as f64 * pr.dx)
            } else {
                (ny as f64 * pr.dx, nx as f64 * pr.dx)
            };
            let exact = w * g.powi(3) * pr.pressure_drop / (12.0 * pr.viscosity * l);
            assert!(
                rel(sol.flow_rate, exact) < 1e-12,
                "{ny}x{nx}: {} vs {exact}",
                sol.flow_rate
            );
            assert!(rel(sol.inlet_flow_rate, exact) < 1e-12);
            assert!(rel(sol.conductance * pr.pressure_drop, exact) < 1e-12);
            assert_eq!(sol.n_unknowns, ny * nx);
        }
    }
}

#[test]
fn parallel_plates_exact_multigrid() {
    for &(ny, nx, periodic) in &[
        (1, 1, false),
        (7, 5, false),
        (40, 33, true),
        (65, 300, false),
    ] {
        for axis in 0..2 {
            let g = 0.37;
            let gap = vec![g; ny * nx];
            let pr = problem(&gap, ny, nx, axis, periodic);
            let sol = solve(
                &pr,
                &Options {
                    solver: Solver::Multigrid,
                    ..Options::default()
                },
            )
            .unwrap();
            let (w, l) = if axis == 0 {
                (nx as f64 * pr.dx, ny as f64 * pr.dx)
            } else {
                (ny as f64 * pr.dx, nx as f64 * pr.dx)
            };
            let exact = w * g.powi(3) * pr.pressure_drop / (12.0 * pr.viscosity * l);
            assert!(
                rel(sol.flow_rate, exact) < 1e-12,
                "{ny}x{nx}: {} vs {exact}",
                sol.flow_rate
            );
            assert!(rel(sol.inlet_flow_rate, exact) < 1e-12);
            assert!(rel(sol.conductance * pr.pressure_drop, exact) < 1e-12);
            assert_eq!(sol.n_unknowns, ny * nx);
        }
    }
}

#[test]
fn one_dimensional_gap_series_conductances() {
    let (ny, nx) = (50, 6);
    let gi: Vec<f64> = (0..ny).map(|i| 0.1 + 0.02 * i as f64).collect();
    let gap: Vec<f64> = (0..ny * nx).map(|k| gi[k / nx]).collect();
    let pr = problem(&gap, ny, nx, 0, false);
    let sol = solve(&pr, &Options::default()).unwrap();
    let c: Vec<f64> = gi
        .iter()
        .map(|g| g.powi(3) / (12.0 * pr.viscosity))
        .collect();
    let mut r = 1.0 / (2.0 * c[0]) + 1.0 / (2.0 * c[ny - 1]);
    for i in 0..ny - 1 {
        r += (c[i] + c[i + 1]) / (2.0 * c[i] * c[i + 1]);
    }
    let exact = nx as f64 * pr.pressure_drop / r;
    assert!(
        rel(sol.flow_rate, exact) < 1e-12,
        "{} vs {exact}",
        sol.flow_rate
    );
    // No flux across the flow.
    assert!(sol.flux_axis1.iter().all(|&v| v.abs() < 1e-14 * exact));
}

#[test]
fn transposed_field_along_axis1_is_the_same_flow() {
    let (ny, nx) = (37, 52);
    let gap = random_gap(3, ny * nx, 0.3);
    let gt: Vec<f64> = (0..ny * nx).map(|k| gap[(k % ny) * nx + k / ny]).collect();
    for periodic in [false, true] {
        let a = solve(&problem(&gap, ny, nx, 0, periodic), &Options::default()).unwrap();
        let b = solve(&problem(&gt, nx, ny, 1, periodic), &Options::default()).unwrap();
        assert_eq!(a.flow_rate.to_bits(), b.flow_rate.to_bits());
        for i in 0..ny {
            for j in 0..nx {
                let (pa, pb) = (a.pressure[i * nx + j], b.pressure[j * ny + i]);
                assert!(pa.to_bits() == pb.to_bits(), "{pa} {pb}");
            }
        }
        for i in 0..=ny {
            for j in 0..nx {
                assert_eq!(a.flux_axis0[i * nx + j], b.flux_axis1[j * (ny + 1) + i]);
            }
        }
    }
}

#[test]
fn transposed_field_along_axis1_is_the_same_flow_multigrid() {
    let (ny, nx) = (37, 52);
    let gap = random_gap(3, ny * nx, 0.3);
    let gt: Vec<f64> = (0..ny * nx).map(|k| gap[(k % ny) * nx + k / ny]).collect();
    for periodic in [false, true] {
        let a = solve(
            &problem(&gap, ny, nx, 0, periodic),
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        )
        .unwrap();
        let b = solve(
            &problem(&gt, nx, ny, 1, periodic),
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        )
        .unwrap();
        assert_eq!(a.flow_rate.to_bits(), b.flow_rate.to_bits());
        for i in 0..ny {
            for j in 0..nx {
                let (pa, pb) = (a.pressure[i * nx + j], b.pressure[j * ny + i]);
                assert!(pa.to_bits() == pb.to_bits(), "{pa} {pb}");
            }
        }
        for i in 0..=ny {
            for j in 0..nx {
                assert_eq!(a.flux_axis0[i * nx + j], b.flux_axis1[j * (ny + 1) + i]);
            }
        }
    }
}

#[test]
fn nothing_spans_gives_exactly_zero() {
    let (ny, nx) = (20, 15);
    let mut gap = random_gap(5, ny * nx, 0.1);
    for j in 0..nx {
        gap[9 * nx + j] = 0.0;
    }
    let sol = solve(&problem(&gap, ny, nx, 0, true), &Options::default()).unwrap();
    assert_eq!(sol.flow_rate, 0.0);
    assert_eq!(sol.inlet_flow_rate, 0.0);
    assert_eq!(sol.n_unknowns, 0);
    assert!(sol
        .flux_axis0
        .iter()
        .chain(&sol.flux_axis1)
        .all(|&v| v == 0.0));
    // Inlet side at Δp, outlet side at 0, the blocking row NaN.
    for j in 0..nx {
        if gap[j] > 0.0 {
            assert_eq!(sol.pressure[j], 3.0);
        }
        if gap[(ny - 1) * nx + j] > 0.0 {
            assert_eq!(sol.pressure[(ny - 1) * nx + j], 0.0);
        }
        assert!(sol.pressure[9 * nx + j].is_nan());
    }
}

#[test]
fn conservation_and_inlet_equals_outlet() {
    let (ny, nx) = (64, 64);
    let gap = random_gap(9, ny * nx, 0.35);
    let sol = solve(&problem(&gap, ny, nx, 0, false), &Options::default()).unwrap();
    assert!(sol.flow_rate > 0.0);
    assert!(rel(sol.inlet_flow_rate, sol.flow_rate) < 1e-9);
    assert!(sol.conservation < 1e-9, "{}", sol.conservation);
    assert!(sol.residual <= 1e-11);
}

#[test]
fn conservation_and_inlet_equals_outlet_multigrid() {
    let (ny, nx) = (64, 64);
    let gap = random_gap(9, ny * nx, 0.35);
    let sol = solve(
        &problem(&gap, ny, nx, 0, false),
        &Options {
            solver: Solver::Multigrid,
            ..Options::default()
        },
    )
    .unwrap();
    assert!(sol.flow_rate > 0.0);
    assert!(rel(sol.inlet_flow_rate, sol.flow_rate) < 1e-9);
    assert!(sol.conservation < 1e-9, "{}", sol.conservation);
    assert!(sol.residual <= 1e-11);
}

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
            let (i, j) = (k / nx, k % nx);
            if i > 0 {
                stack.push(k - nx);
            }
            if i + 1 < ny {
                stack.push(k + nx);
            }
            if j > 0 {
                stack.push(k - 1);
            } else if periodic {
                stack.push(k + nx - 1);
            }
            if j + 1 < nx {
                stack.push(k + 1);
            } else if periodic {
                stack.push(k + 1 - nx);
            }
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
        let (i, j) = (k / nx, k % nx);
        let mut nbs = vec![];
        if i > 0 {
            nbs.push(k - nx);
        }
        if i + 1 < ny {
            nbs.push(k + nx);
        }
        if j > 0 {
            nbs.push(k - 1);
        } else if periodic && nx > 1 {
            nbs.push(k + nx - 1);
        }
        if j + 1 < nx {
            nbs.push(k + 1);
        } else if periodic && nx > 1 {
            nbs.push(k + 1 - nx);
        }
        for q in nbs {
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

#[test]
fn matches_dense_cholesky_reference() {
    for (seed, ny, nx, periodic, closed) in [
        (1, 30, 41, false, 0.3),
        (2, 45, 45, true, 0.35),
        (4, 70, 20, false, 0.2),
        (6, 3, 90, true, 0.4),
    ] {
        let gap = random_gap(seed, ny * nx, closed);
        let pr = problem(&gap, ny, nx, 0, periodic);
        let sol = solve(&pr, &Options::default()).unwrap();
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
fn matches_dense_cholesky_reference_multigrid() {
    for (seed, ny, nx, periodic, closed) in [
        (1, 30, 41, false, 0.3),
        (2, 45, 45, true, 0.35),
        (4, 70, 20, false, 0.2),
        (6, 3, 90, true, 0.4),
    ] {
        let gap = random_gap(seed, ny * nx, closed);
        let pr = problem(&gap, ny, nx, 0, periodic);
        let sol = solve(
            &pr,
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        )
        .unwrap();
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
fn same_bits_on_one_and_two_threads() {
    let (ny, nx) = (300, 260);
    let gap = random_gap(11, ny * nx, 0.3);
    let run = |t: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        pool.install(|| solve(&problem(&gap, ny, nx, 0, true), &Options::default()).unwrap())
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
fn same_bits_on_one_and_two_threads_multigrid() {
    let (ny, nx) = (300, 260);
    let gap = random_gap(11, ny * nx, 0.3);
    let run = |t: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(t)
            .build()
            .unwrap();
        pool.install(|| {
            solve(
                &problem(&gap, ny, nx, 0, true),
                &Options {
                    solver: Solver::Multigrid,
                    ..Options::default()
                },
            )
            .unwrap()
        })
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
fn contact_mask_closes_cells_and_bad_input_is_refused() {
    let (ny, nx) = (10, 10);
    let gap = vec![1.0; ny * nx];
    let mut contact = vec![false; ny * nx];
    for j in 0..nx {
        contact[4 * nx + j] = true;
    }
    let mut pr = problem(&gap, ny, nx, 0, false);
    pr.contact = Some(&contact);
    assert_eq!(solve(&pr, &Options::default()).unwrap().flow_rate, 0.0);
    // The mask across the flow leaves the axis-1 flow untouched but for the closed row.
    pr.axis = 1;
    let s = solve(&pr, &Options::default()).unwrap();
    let exact = 9.0 * pr.pressure_drop / (12.0 * pr.viscosity * 10.0);
    assert!(rel(s.flow_rate, exact) < 1e-12);

    let mut bad = gap.clone();
    bad[5] = f64::NAN;
    let e = solve(&problem(&bad, ny, nx, 0, false), &Options::default()).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "gap", .. }));
    bad[5] = -1.0;
    let e = solve(&problem(&bad, ny, nx, 0, false), &Options::default()).unwrap_err();
    assert!(matches!(e, Error::InvalidArgument { name: "gap", .. }));
    let mut pr = problem(&gap, ny, nx, 0, false);
    pr.viscosity = 0.0;
    assert!(matches!(
        solve(&pr, &Options::default()).unwrap_err(),
        Error::InvalidArgument {
            name: "viscosity",
            ..
        }
    ));
    let small = Options {
        memory_limit: Some(1000),
        ..Options::default()
    };
    assert!(matches!(
        solve(&problem(&gap, ny, nx, 0, false), &small).unwrap_err(),
        Error::TooLarge { .. }
    ));
}

#[test]
fn multigrid_keeps_iterations_low() {
    // Plain aggregation alone needs ~50 iterations on plates at 513² and grows with the
    // number of levels; the K-cycle keeps it flat.
    let (ny, nx) = (513, 513);
    let mg = Options {
        solver: Solver::Multigrid,
        ..Options::default()
    };
    let gap = vec![1.0; ny * nx];
    let sol = solve(&problem(&gap, ny, nx, 0, false), &mg).unwrap();
    assert!(sol.iterations <= 30, "{}", sol.iterations);
    let gap = random_gap(13, ny * nx, 0.0);
    let sol = solve(&problem(&gap, ny, nx, 0, false), &mg).unwrap();
    assert!(sol.iterations <= 80, "{}", sol.iterations);
}

/// A perfect maze (randomised depth-first carving) of one-cell-wide corridors on a
/// `(2h + 1) × (2w + 1)` grid, one opening on the inlet row and one on the outlet row, gaps
/// log-uniform over `decades` decades. Closed cells have gap 0.
fn maze_gap(seed: u64, h: usize, w: usize, decades: f64) -> (Vec<f64>, usize, usize) {
    let (ny, nx) = (2 * h + 1, 2 * w + 1);
    let mut open = vec![false; ny * nx];
    let u = lcg(seed, 4 * h * w + ny * nx);
    let mut draw = 0;
    let mut seen = vec![false; h * w];
    let mut stack = vec![(0usize, 0usize)];
    seen[0] = true;
    open[nx + 1] = true;
    while let Some(&(a, b)) = stack.last() {
        let mut nb = Vec::with_capacity(4);
        if a > 0 && !seen[(a - 1) * w + b] {
            nb.push((a - 1, b));
        }
        if a + 1 < h && !seen[(a + 1) * w + b] {
            nb.push((a + 1, b));
        }
        if b > 0 && !seen[a * w + b - 1] {
            nb.push((a, b - 1));
        }
        if b + 1 < w && !seen[a * w + b + 1] {
            nb.push((a, b + 1));
        }
        if nb.is_empty() {
            stack.pop();
            continue;
        }
        let pick = nb[((u[draw % u.len()] * nb.len() as f64) as usize).min(nb.len() - 1)];
        draw += 1;
        seen[pick.0 * w + pick.1] = true;
        open[(2 * pick.0 + 1) * nx + 2 * pick.1 + 1] = true;
        // The wall cell between the two maze cells.
        open[(a + pick.0 + 1) * nx + b + pick.1 + 1] = true;
        stack.push(pick);
    }
    open[1] = true; // inlet opening
    open[(ny - 1) * nx + nx - 2] = true; // outlet opening
    let v = lcg(seed ^ 0x5eed, ny * nx);
    let gap = (0..ny * nx)
        .map(|k| {
            if open[k] {
                10f64.powf(-decades * v[k] / 3.0)
            } else {
                0.0
            }
        })
        .collect();
    (gap, ny, nx)
}

/// Open cells the way the solver defines them, 4-connectivity, no wrap: the cells of the one
/// inlet-to-outlet path of a perfect maze (a plain breadth-first search from the inlet
/// opening, then back along the parents from the outlet opening).
fn maze_path(gap: &[f64], ny: usize, nx: usize) -> Vec<usize> {
    let start = (0..nx).find(|&j| gap[j] > 0.0).unwrap();
    let goal = (ny - 1) * nx + (0..nx).find(|&j| gap[(ny - 1) * nx + j] > 0.0).unwrap();
    let mut parent = vec![usize::MAX; ny * nx];
    parent[start] = start;
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(k) = queue.pop_front() {
        let (i, j) = (k / nx, k % nx);
        let mut nbs = Vec::new();
        if i > 0 {
            nbs.push(k - nx);
        }
        if i + 1 < ny {
            nbs.push(k + nx);
        }
        if j > 0 {
            nbs.push(k - 1);
        }
        if j + 1 < nx {
            nbs.push(k + 1);
        }
        for l in nbs {
            if gap[l] > 0.0 && parent[l] == usize::MAX {
                parent[l] = k;
                queue.push_back(l);
            }
        }
    }
    let mut path = vec![goal];
    while *path.last().unwrap() != start {
        path.push(parent[*path.last().unwrap()]);
    }
    path.reverse();
    path
}

/// Random site field near the 4-connectivity site-percolation threshold (open fraction
/// `open`, ≈ 0.593 at threshold), gaps log-uniform over `decades` decades of `g³`.
fn threshold_gap(seed: u64, n: usize, open: f64, decades: f64) -> Vec<f64> {
    let u = lcg(seed, 2 * n);
    (0..n)
        .map(|k| {
            if u[n + k] < open {
                10f64.powf(-decades * u[k] / 3.0)
            } else {
                0.0
            }
        })
        .collect()
}

#[test]
#[ignore]
fn experiment_near_threshold() {
    let n: usize = std::env::var("EXP_N")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(513);
    let dec: f64 = std::env::var("EXP_DEC")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8.0);
    for (name, gap, ny, nx) in [
        {
            let (g, ny, nx) = maze_gap(3, n / 2, n / 2, dec);
            ("maze", g, ny, nx)
        },
        ("site 0.60", threshold_gap(5, n * n, 0.60, dec), n, n),
        ("site 0.62", threshold_gap(6, n * n, 0.62, dec), n, n),
    ] {
        let pr = problem(&gap, ny, nx, 0, false);
        if name == "maze" {
            let path = maze_path(&gap, ny, nx);
            let cc = |k: usize| gap[k].powi(3) / (12.0 * pr.viscosity);
            let mut r = 1.0 / (2.0 * cc(path[0])) + 1.0 / (2.0 * cc(*path.last().unwrap()));
            for w in path.windows(2) {
                r += 1.0 / assemble::harmonic(cc(w[0]), cc(w[1]));
            }
            println!(
                "maze oracle Q {:.12e} path {}",
                pr.pressure_drop / r,
                path.len()
            );
        }
        let t = std::time::Instant::now();
        let a = solve(
            &pr,
            &Options {
                solver: Solver::Cholesky,
                ..Options::default()
            },
        )
        .unwrap();
        let ta = t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        let b = solve(
            &pr,
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        );
        let tb = t.elapsed().as_secs_f64();
        match b {
            Ok(b) => println!(
                "{name}: unknowns {} chol {ta:.2}s Q {:.12e} in/out {:.1e} | mg {tb:.2}s it {} Q rel {:.1e} in/out {:.1e} res {:.1e} cons {:.1e}",
                a.n_unknowns,
                a.flow_rate,
                rel(a.inlet_flow_rate, a.flow_rate),
                b.iterations,
                rel(b.flow_rate, a.flow_rate),
                rel(b.inlet_flow_rate, b.flow_rate),
                b.residual,
                b.conservation
            ),
            Err(e) => println!(
                "{name}: chol {ta:.2}s Q {:.12e} in {:.12e}; mg {tb:.2}s error {e}",
                a.flow_rate, a.inlet_flow_rate
            ),
        }
    }
}

fn forced(solver: Solver) -> Options<'static> {
    Options {
        solver,
        ..Options::default()
    }
}

/// Flow along a one-cell-wide winding channel: the series resistance of the faces on the
/// one inlet-to-outlet path (found by breadth-first search), dead ends carrying nothing.
fn maze_oracle(gap: &[f64], ny: usize, nx: usize, pr: &Problem<'_>) -> f64 {
    let path = maze_path(gap, ny, nx);
    let c = |k: usize| gap[k].powi(3) / (12.0 * pr.viscosity);
    let mut r = 1.0 / (2.0 * c(path[0])) + 1.0 / (2.0 * c(*path.last().unwrap()));
    for w in path.windows(2) {
        r += 1.0 / assemble::harmonic(c(w[0]), c(w[1]));
    }
    pr.pressure_drop / r
}

#[test]
fn winding_channel_matches_series_resistance() {
    // Conductances g³ over 2 decades: every solver must give the path's series resistance.
    let (gap, ny, nx) = maze_gap(3, 64, 64, 2.0);
    let pr = problem(&gap, ny, nx, 0, false);
    let q = maze_oracle(&gap, ny, nx, &pr);
    for solver in [Solver::Auto, Solver::Cholesky, Solver::Multigrid] {
        let sol = solve(&pr, &forced(solver)).unwrap();
        assert!(
            rel(sol.flow_rate, q) < 1e-10,
            "{solver:?}: {} vs {q}",
            sol.flow_rate
        );
        assert!(rel(sol.inlet_flow_rate, q) < 1e-9, "{solver:?}");
        assert!(sol.conservation < 1e-9, "{solver:?}: {}", sol.conservation);
    }
}

#[test]
fn near_threshold_multigrid_matches_cholesky() {
    // Site fields just above the percolation threshold (tortuous spanning cluster, dead
    // ends everywhere), conductances over 2 and 4 decades, and a maze over 4 decades.
    let n = 129;
    let cases: Vec<(Vec<f64>, usize, usize, f64)> = vec![
        (threshold_gap(5, n * n, 0.60, 2.0), n, n, 1e-10),
        (threshold_gap(6, n * n, 0.62, 2.0), n, n, 1e-10),
        (threshold_gap(5, n * n, 0.60, 4.0), n, n, 1e-10),
        (threshold_gap(6, n * n, 0.62, 4.0), n, n, 1e-10),
        {
            let (g, ny, nx) = maze_gap(3, 64, 64, 4.0);
            (g, ny, nx, 1e-9)
        },
    ];
    for (k, (gap, ny, nx, tol)) in cases.into_iter().enumerate() {
        let pr = problem(&gap, ny, nx, 0, false);
        let a = solve(&pr, &forced(Solver::Cholesky)).unwrap();
        let b = solve(&pr, &forced(Solver::Multigrid)).unwrap();
        assert!(a.flow_rate > 0.0);
        assert!(
            rel(b.flow_rate, a.flow_rate) < tol,
            "case {k}: {} vs {}",
            b.flow_rate,
            a.flow_rate
        );
        assert!(rel(b.inlet_flow_rate, b.flow_rate) < 1e-9, "case {k}");
        assert!(rel(a.inlet_flow_rate, a.flow_rate) < 1e-9, "case {k}");
    }
}

#[test]
fn multigrid_never_returns_a_biased_rate() {
    // Eight decades of g³ on a maze and near-threshold fields: the forced multigrid either
    // meets its flow-rate test (and then agrees with the factorisation) or says it did not;
    // the default solver always answers.
    let n = 129;
    let mut cases = vec![
        (threshold_gap(5, n * n, 0.60, 8.0), n, n),
        (threshold_gap(6, n * n, 0.62, 8.0), n, n),
    ];
    let (g, ny, nx) = maze_gap(3, 64, 64, 8.0);
    cases.push((g, ny, nx));
    for (k, (gap, ny, nx)) in cases.into_iter().enumerate() {
        let pr = problem(&gap, ny, nx, 0, false);
        let a = solve(&pr, &forced(Solver::Cholesky)).unwrap();
        let mg = Options {
            solver: Solver::Multigrid,
            max_iter: Some(2000),
            ..Options::default()
        };
        match solve(&pr, &mg) {
            Ok(b) => {
                assert!(
                    rel(b.inlet_flow_rate, b.flow_rate) <= FLUX_AGREEMENT,
                    "case {k}"
                );
                assert!(rel(b.flow_rate, a.flow_rate) < 1e-6, "case {k}");
            }
            Err(e) => assert!(matches!(e, Error::NotConverged { .. }), "case {k}: {e}"),
        }
        let auto = Options {
            max_iter: Some(2000),
            ..Options::default()
        };
        let c = solve(&pr, &auto).unwrap();
        assert!(rel(c.flow_rate, a.flow_rate) < 1e-6, "case {k}");
    }
}

#[test]
fn cholesky_on_a_winding_channel_over_eight_decades() {
    // g³ over 8 decades along one winding one-cell channel (condition number near 1/ε):
    // the factor keeps ~1e-6 of the rate; refinement must not make it worse, and both ends
    // must still give the path's series resistance to that.
    let (gap, ny, nx) = maze_gap(3, 64, 64, 8.0);
    let pr = problem(&gap, ny, nx, 0, false);
    let q = maze_oracle(&gap, ny, nx, &pr);
    let sol = solve(&pr, &forced(Solver::Cholesky)).unwrap();
    assert_eq!(sol.solver, "cholesky");
    assert!(rel(sol.flow_rate, q) < 1e-5, "{} vs {q}", sol.flow_rate);
    assert!(
        rel(sol.inlet_flow_rate, q) < 1e-5,
        "{} vs {q}",
        sol.inlet_flow_rate
    );
}

#[test]
fn auto_uses_the_multigrid_when_the_factor_does_not_fit() {
    let n = 96;
    let gap = random_gap(11, n * n, 0.3);
    let pr = problem(&gap, n, n, 0, false);
    let exact = solve(&pr, &forced(Solver::Cholesky)).unwrap();
    assert_eq!(exact.solver, "cholesky");
    // Room for the rest of the solve but not for the factor.
    let tight = multigrid_estimate(n * n, n * n) + 1024;
    let auto = Options {
        memory_limit: Some(tight),
        ..Options::default()
    };
    let sol = solve(&pr, &auto).unwrap();
    assert_eq!(sol.solver, "multigrid");
    assert!(sol.iterations > 0);
    assert!(rel(sol.flow_rate, exact.flow_rate) < 1e-10);
    let chol = Options {
        memory_limit: Some(tight),
        ..forced(Solver::Cholesky)
    };
    assert!(matches!(solve(&pr, &chol), Err(Error::TooLarge { .. })));
}

#[test]
fn auto_skips_the_factor_from_multigrid_from_unknowns() {
    // Ample room: the factor below the threshold, the multigrid from it.
    let ample = Some(u64::MAX / 2);
    assert!(!axis0::auto_skips_factor(MULTIGRID_FROM - 1, ample));
    assert!(!axis0::auto_skips_factor(MULTIGRID_FROM - 1, None));
    assert!(axis0::auto_skips_factor(MULTIGRID_FROM, ample));
    assert!(axis0::auto_skips_factor(MULTIGRID_FROM, None));
    // Few unknowns, but not even the factor's lower bound fits.
    assert!(axis0::auto_skips_factor(1000, Some(1024)));
}

/// `order_of` orders every unknown of the stencil of conductances `c` exactly once.
fn assert_orders_every_unknown(
    c: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
    order_of: fn(&assemble::Stencil, &[usize], usize) -> Vec<usize>,
) {
    let (st, _) = assemble::fine_stencil(c, ny, nx, periodic);
    let mut index = vec![usize::MAX; ny * nx];
    let mut m = 0;
    for (k, slot) in index.iter_mut().enumerate() {
        if st.active[k] {
            *slot = m;
            m += 1;
        }
    }
    let mut order = order_of(&st, &index, m);
    assert_eq!(order.len(), m, "{ny}x{nx} periodic={periodic}");
    order.sort_unstable();
    assert!(order.iter().enumerate().all(|(q, &u)| q == u));
}

#[test]
fn the_order_is_a_permutation_of_the_unknowns_with_and_without_blocks() {
    // 7 × 9 and 40 × 30 are ordered by 2 × 2 blocks, 150 × 150 cell by cell; about a third
    // of the cells closed.
    for &(ny, nx) in &[(7usize, 9usize), (40, 30), (150, 150), (1, 5)] {
        for periodic in [false, true] {
            let c: Vec<f64> = lcg((ny * 1000 + nx) as u64, ny * nx)
                .into_iter()
                .map(|u| if u < 0.35 { 0.0 } else { u })
                .collect();
            assert_orders_every_unknown(&c, ny, nx, periodic, order::ordering);
        }
    }
}

/// The nested dissection orders every unknown once, on thin and square grids, open and with
/// about a third of the cells closed, with and without wrap; and a mostly open grid above
/// its size threshold (ordered by it) gives the multigrid's flow rate.
#[test]
fn the_nested_dissection_is_a_permutation_and_gives_the_flow() {
    for &(ny, nx) in &[
        (1usize, 5usize),
        (2, 40),
        (3, 3),
        (40, 1),
        (77, 130),
        (200, 200),
    ] {
        for closed in [0.0, 0.35] {
            for periodic in [false, true] {
                let c: Vec<f64> = lcg((ny * 1000 + nx) as u64, ny * nx)
                    .into_iter()
                    .map(|u| if u < closed { 0.0 } else { u })
                    .collect();
                assert_orders_every_unknown(&c, ny, nx, periodic, order::nd_order);
            }
        }
    }
    let (ny, nx) = (300, 300);
    let gap: Vec<f64> = lcg(5, ny * nx)
        .into_iter()
        .map(|u| if u < 0.1 { 0.0 } else { 0.2 + u })
        .collect();
    for periodic in [false, true] {
        let pr = problem(&gap, ny, nx, 0, periodic);
        let direct = solve(&pr, &Options::default()).unwrap();
        assert_eq!(direct.solver, "cholesky");
        let mg = solve(
            &pr,
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        )
        .unwrap();
        let rel = (direct.flow_rate - mg.flow_rate).abs() / mg.flow_rate;
        assert!(rel < 1e-9, "{} {} {rel:e}", direct.flow_rate, mg.flow_rate);
    }
}

/// A kept analysis: a gap closing in steps (`g − kδ`), each step solved on the analysis of
/// the first while its unknowns stay among them and above the reuse fraction; the rates as
/// a fresh analysis's to 1e-10, a different grid or a more open gap analysed afresh.
#[test]
fn kept_analysis_gives_the_fresh_rate() {
    let (ny, nx) = (70, 90);
    let base: Vec<f64> = lcg(21, ny * nx).into_iter().map(|u| 0.05 + u).collect();
    let kept = kept::KeptAnalysis::new(0);
    let opts = Options {
        analysis: Some(&kept),
        ..Options::default()
    };
    for k in 0..4 {
        let gap: Vec<f64> = base
            .iter()
            .map(|g| (g - 0.01 * k as f64).max(0.0))
            .collect();
        let pr = problem(&gap, ny, nx, 0, true);
        let a = solve(&pr, &opts).unwrap();
        let f = solve(&pr, &Options::default()).unwrap();
        assert_eq!(a.n_unknowns, f.n_unknowns);
        let rel = (a.flow_rate - f.flow_rate).abs() / f.flow_rate;
        assert!(rel <= 1e-10, "step {k}: {rel:e}");
    }
    assert_eq!(kept.made() + kept.reused(), 4);
    assert!(kept.reused() >= 1, "{} {}", kept.made(), kept.reused());
    // Another grid: a new analysis, no out-of-range access.
    let made = kept.made();
    let pr = problem(&base[..(ny - 1) * nx], ny - 1, nx, 0, true);
    solve(&pr, &opts).unwrap();
    assert_eq!(kept.made(), made + 1);
}

/// A column of wide cells with two necks: the wide cells between them are joined to the rest
/// only through faces `g³ ~ 1e-15` of their own, which the rounded diagonal of the assembled
/// matrix loses. The rate is the exact series resistance (a sum of positive terms).
#[test]
fn wide_cells_between_two_necks_give_the_series_rate() {
    for &neck in &[1e-3, 1e-5, 1e-6] {
        let ny = 9;
        let mut gap = vec![1.0; ny];
        gap[3] = neck;
        gap[6] = neck;
        let pr = problem(&gap, ny, 1, 0, false);
        let sol = solve(&pr, &Options::default()).unwrap();
        let c: Vec<f64> = gap
            .iter()
            .map(|g| g * g * g / (12.0 * pr.viscosity))
            .collect();
        let mut r = 1.0 / (2.0 * c[0]) + 1.0 / (2.0 * c[ny - 1]);
        for k in 0..ny - 1 {
            r += (c[k] + c[k + 1]) / (2.0 * c[k] * c[k + 1]);
        }
        let q = pr.pressure_drop / r;
        assert!(
            rel(sol.flow_rate, q) < 1e-13,
            "{neck}: {} vs {q}",
            sol.flow_rate
        );
        assert!(rel(sol.inlet_flow_rate, q) < 1e-13);
        assert!(sol.conservation < 1e-6);
    }
}

/// The cancellation-free elimination against the dense Cholesky reference on a field whose
/// conductances stay within a few decades (where the reference is exact to round-off).
#[test]
fn elimination_matches_the_factor_on_ordinary_gaps() {
    let (ny, nx) = (23, 17);
    let gap = random_gap(11, ny * nx, 0.3);
    let c: Vec<f64> = gap.iter().map(|g| g * g * g).collect();
    let (st, b_in) = assemble::fine_stencil(&c, ny, nx, true);
    let b_out: Vec<f64> = (0..ny * nx)
        .map(|k| if k >= (ny - 1) * nx { 2.0 * c[k] } else { 0.0 })
        .collect();
    let elim = gth::Elimination::new(&st, None).unwrap();
    let mut f = direct::Factor::new(&st, None).unwrap();
    for b in [&b_in, &b_out] {
        let mut x = vec![0.0; ny * nx];
        elim.solve(b, &mut x);
        let mut y = vec![0.0; ny * nx];
        let _ = f.solve(&st, b, &mut y);
        for k in 0..ny * nx {
            if st.active[k] {
                assert!((x[k] - y[k]).abs() < 1e-13, "{k}: {} vs {}", x[k], y[k]);
            }
        }
    }
}

/// A solve handed the labels of its open cells gives the same bits as one that labels them
/// itself, along both axes and with wrap; labels of other cells are refused.
#[test]
fn given_labels_give_the_same_solution() {
    let (ny, nx) = (23, 17);
    let gap = random_gap(11, ny * nx, 0.1);
    let contact: Vec<bool> = lcg(12, ny * nx).iter().map(|&u| u < 0.05).collect();
    for axis in 0..2 {
        for periodic in [false, true] {
            let mut pr = problem(&gap, ny, nx, axis, periodic);
            pr.contact = Some(&contact);
            let open = clusters::OpenCells {
                gap: &gap,
                contact: Some(&contact),
            };
            let per = Periodic {
                axis0: periodic && axis == 1,
                axis1: periodic && axis == 0,
            };
            let mut labels = vec![0u32; ny * nx];
            let k =
                clusters::label_into(&open, ny, nx, Connectivity::Four, per, &mut labels).unwrap();
            let opts = Options::default();
            let a = solve(&pr, &opts).unwrap();
            let b = solve_labelled(&pr, &opts, Some((&labels, k))).unwrap();
            assert!(a.n_unknowns > 0);
            assert_eq!(a.flow_rate.to_bits(), b.flow_rate.to_bits());
            assert_eq!(a.n_unknowns, b.n_unknowns);
            let same = |x: &[f64], y: &[f64]| {
                x.iter()
                    .zip(y)
                    .all(|(p, q)| p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()))
            };
            assert!(same(&a.pressure, &b.pressure));
            assert!(same(&a.flux_axis0, &b.flux_axis0));
            // Labels that miss an open cell are refused.
            let first_open = labels.iter().position(|&l| l != 0).unwrap();
            let mut wrong = labels.clone();
            wrong[first_open] = 0;
            let err = solve_labelled(&pr, &opts, Some((&wrong, k))).unwrap_err();
            assert!(format!("{err}").contains("labels"), "{err}");
        }
    }
}

/// The factored answer carried in two doubles (`split_direct`) against the cancellation-free
/// elimination (`gth`, a second solver whose rates are sums of positive terms) on fields near
/// the percolation threshold whose `g³` spans 6 to 12 decades: the same rates to 1e-13, and
/// the first-order rate errors far below those of the double answer.
#[test]
fn split_refinement_matches_the_elimination_near_threshold() {
    let mut ran = 0;
    for (seed, decades) in [(3u64, 6.0), (5, 9.0), (8, 12.0)] {
        let n = 48;
        let gap = threshold_gap(seed, n * n, 0.62, decades);
        let c: Vec<f64> = gap.iter().map(|g| g * g * g).collect();
        let (st0, _) = assemble::fine_stencil(&c, n, n, true);
        // Unknowns on the spanning clusters only, as the solve has them.
        let open: Vec<bool> = c.iter().map(|&v| v > 0.0).collect();
        let per = Periodic {
            axis0: false,
            axis1: true,
        };
        let (labels, k) = clusters::label(&open, n, n, Connectivity::Four, per).unwrap();
        let mut touch = vec![0u8; k + 1];
        for j in 0..n {
            touch[labels[j] as usize] |= 1;
            touch[labels[(n - 1) * n + j] as usize] |= 2;
        }
        touch[0] = 0;
        let cs: Vec<f64> = c
            .iter()
            .zip(&labels)
            .map(|(&v, &l)| if touch[l as usize] == 3 { v } else { 0.0 })
            .collect();
        drop(st0);
        if cs.iter().all(|&v| v == 0.0) {
            continue;
        }
        let (st, b_in) = assemble::fine_stencil(&cs, n, n, true);
        let b_out: Vec<f64> = (0..n * n)
            .map(|k| if k >= (n - 1) * n { 2.0 * cs[k] } else { 0.0 })
            .collect();
        let (gx, gpsi, _, (gxlo, gpsilo)) = paths::solve_gth(&st, &b_in, &b_out, None).unwrap();
        let q_ref = cg::dot(&b_out, &gx) + cg::dot(&b_out, &gxlo);
        let q_ref_in = cg::dot(&b_in, &gpsi) + cg::dot(&b_in, &gpsilo);
        assert!(rel(q_ref, q_ref_in) < 1e-13);
        let mut f = direct::Factor::new(&st, None).unwrap();
        let a = paths::solve_direct(&mut f, &st, &b_in, &b_out);
        let a = paths::split_direct(&mut f, &st, &b_in, &b_out, a, paths::DIRECT_TRUST);
        assert!(
            paths::trusted(&b_in, &b_out, &a, paths::DIRECT_TRUST),
            "seed {seed}"
        );
        assert!(
            a.residual() < 1e-16,
            "seed {seed}: residual {:e}",
            a.residual()
        );
        let q = cg::dot(&b_out, &a.x) + cg::dot(&b_out, &a.lo.0);
        let q_in = cg::dot(&b_in, &a.psi) + cg::dot(&b_in, &a.lo.1);
        assert!(rel(q, q_ref) < 1e-13, "seed {seed}: {q:e} vs {q_ref:e}");
        assert!(
            rel(q_in, q_ref) < 1e-13,
            "seed {seed}: {q_in:e} vs {q_ref:e}"
        );
        ran += 1;
    }
    assert_eq!(ran, 3);
}
