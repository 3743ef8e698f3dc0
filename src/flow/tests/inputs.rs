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
    assert!(!axis0::auto_skips_factor(MULTIGRID_FROM - 1, ample));
    assert!(!axis0::auto_skips_factor(MULTIGRID_FROM - 1, None));
    assert!(axis0::auto_skips_factor(MULTIGRID_FROM, ample));
    assert!(axis0::auto_skips_factor(MULTIGRID_FROM, None));
    // Few unknowns, but not even the factor's lower bound fits.
    assert!(axis0::auto_skips_factor(1000, Some(1024)));
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
