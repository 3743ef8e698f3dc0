//! What the caller passes: the contact mask, given cluster labels, bad input, and the
//! automatic choice of solver.
use super::*;

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
    assert!(!axis0::auto_skips_factor(
        MULTIGRID_FROM - 1,
        MULTIGRID_FROM,
        ample
    ));
    assert!(!axis0::auto_skips_factor(
        MULTIGRID_FROM - 1,
        MULTIGRID_FROM,
        None
    ));
    assert!(axis0::auto_skips_factor(
        MULTIGRID_FROM,
        MULTIGRID_FROM,
        ample
    ));
    assert!(axis0::auto_skips_factor(
        MULTIGRID_FROM,
        MULTIGRID_FROM,
        None
    ));
    // Few unknowns, but not even the factor's lower bound fits.
    assert!(axis0::auto_skips_factor(1000, MULTIGRID_FROM, Some(1024)));
}

/// Below its size threshold `Auto` weighs the factor against the multigrid once the
/// analysis is known: with the default rates the factor on a small grid, with a free
/// multigrid (0 s per unknown) the multigrid, whose rate matches the factor's.
#[test]
fn auto_takes_the_multigrid_when_it_is_predicted_faster() {
    let n = 96;
    let gap = random_gap(12, n * n, 0.3);
    let pr = problem(&gap, n, n, 0, true);
    let exact = solve(&pr, &forced(Solver::Cholesky)).unwrap();
    assert_eq!(solve(&pr, &Options::default()).unwrap().solver, "cholesky");
    let free = Options {
        multigrid_seconds_per_unknown: 0.0,
        ..Options::default()
    };
    let sol = solve(&pr, &free).unwrap();
    assert_eq!(sol.solver, "multigrid");
    assert!(sol.iterations > 0);
    assert!(rel(sol.flow_rate, exact.flow_rate) < 1e-10);
    assert!(rel(sol.inlet_flow_rate, exact.flow_rate) < 1e-10);
}

/// A gap of random widths in [0.5, 1) on an `n × n` wrapped grid with a walled 21 × 21
/// pocket joined to the rest through two cells of gap `neck`, in its left and right walls
/// (so that it is not a dead end); and the contact mask, with the necks closed too when
/// `sealed`.
fn pocket_gap(n: usize, neck: f64, sealed: bool) -> (Vec<f64>, Vec<bool>) {
    let mut gap: Vec<f64> = lcg(21, n * n).iter().map(|&u| 0.5 + 0.5 * u).collect();
    let mut contact = vec![false; n * n];
    let (a, b) = (n / 3, n / 3 + 22);
    for t in a..=b {
        for k in [a * n + t, b * n + t, t * n + a, t * n + b] {
            contact[k] = true;
        }
    }
    let m = (a + b) / 2;
    for k in [m * n + a, m * n + b] {
        gap[k] = neck;
        contact[k] = sealed;
    }
    (gap, contact)
}

/// `Auto` from its multigrid threshold runs the multigrid first; on a pocket joined through
/// necks whose `g³` is below single precision the multigrid refuses, and `Auto` answers with
/// the factor when it fits. The necks carry ~1e-60 of the flow: the rate is that of the gap
/// with the pocket sealed, which the multigrid solves.
#[test]
fn auto_answers_with_the_factor_where_the_multigrid_refuses() {
    let n = 97;
    let (gap, contact) = pocket_gap(n, 1e-20, false);
    let mut pr = problem(&gap, n, n, 0, true);
    pr.contact = Some(&contact);
    let refused = solve(&pr, &forced(Solver::Multigrid)).unwrap_err();
    assert!(matches!(refused, Error::NotConverged { .. }), "{refused}");
    let first = Options {
        multigrid_from: 1,
        ..Options::default()
    };
    let sol = solve(&pr, &first).unwrap();
    assert_eq!(sol.solver, "cholesky");
    // The same below the threshold when the multigrid is taken as the predicted faster.
    let weighed = Options {
        multigrid_seconds_per_unknown: 0.0,
        ..Options::default()
    };
    let by_cost = solve(&pr, &weighed).unwrap();
    assert_eq!(by_cost.solver, "cholesky");
    assert_eq!(by_cost.flow_rate.to_bits(), sol.flow_rate.to_bits());

    let (gap_s, contact_s) = pocket_gap(n, 1e-20, true);
    let mut sealed = problem(&gap_s, n, n, 0, true);
    sealed.contact = Some(&contact_s);
    let oracle = solve(&sealed, &forced(Solver::Multigrid)).unwrap();
    assert_eq!(oracle.solver, "multigrid");
    assert!(
        rel(sol.flow_rate, oracle.flow_rate) < 1e-10,
        "{} {}",
        sol.flow_rate,
        oracle.flow_rate
    );
    assert!(rel(sol.inlet_flow_rate, oracle.flow_rate) < 1e-10);
    // Without room for the factor, the multigrid's refusal is the answer.
    let tight = Options {
        multigrid_from: 1,
        memory_limit: Some(multigrid_estimate(n * n, n * n) + 1024),
        ..Options::default()
    };
    let e = solve(&pr, &tight).unwrap_err();
    assert!(matches!(e, Error::NotConverged { .. }), "{e}");
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
