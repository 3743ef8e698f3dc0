//! Gaps near the percolation threshold, conductances over many decades: the multigrid,
//! the factor and the cancellation-free elimination agree, and no rate is returned biased.
use super::*;

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
        let mut spare = crate::alloc::ZeroedByIdle::new(0, n * n);
        let a = paths::solve_direct(&mut f, &st, &b_in, &b_out, &mut spare);
        let a = paths::split_direct(
            &mut f,
            &st,
            &b_in,
            &b_out,
            a,
            paths::DIRECT_TRUST,
            &mut spare,
        );
        assert!(paths::trusted(&a, paths::DIRECT_TRUST), "seed {seed}");
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
