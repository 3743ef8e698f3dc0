//! Trivial states, bad input refused, and a caller's kernel table.
use super::*;

#[test]
fn trivial_states() {
    let (ny, nx) = (10usize, 9usize);
    let h = rough(ny, nx, 4);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        // Δ = 0: nothing is pressed, p = 0 without iterating.
        let s = solve(&pr, Control::Approach(0.0), &Options::default(), None).unwrap();
        assert_eq!(s.iterations, 0);
        assert!(s.pressure.iter().all(|&v| v == 0.0));
        assert_eq!(s.kkt, 0.0);
    }
    // A flat surface: free punch (displacement and load control agree).
    let flat = vec![0.5; ny * nx];
    let pr = problem(&flat, ny, nx, Boundary::Free);
    let d = solve(&pr, Control::Approach(0.1), &Options::default(), None).unwrap();
    assert_eq!(d.contact_points, ny * nx);
    let l = solve(
        &pr,
        Control::MeanPressure(d.mean_pressure),
        &Options::default(),
        None,
    )
    .unwrap();
    assert!((l.approach - 0.1).abs() < 1e-8);
    // One point.
    let one = [3.0];
    let pr = problem(&one, 1, 1, Boundary::Free);
    let s = solve(&pr, Control::MeanPressure(2.0), &Options::default(), None).unwrap();
    assert!((s.pressure[0] - 2.0).abs() < 1e-12);
}

#[test]
fn bad_inputs_are_errors() {
    let (ny, nx) = (6usize, 5usize);
    let h = rough(ny, nx, 9);
    let pr = problem(&h, ny, nx, Boundary::Free);
    let name = |r: Result<Solution>| match r {
        Err(Error::InvalidArgument { name, .. }) => name,
        other => panic!("{other:?}"),
    };
    let d = Control::Approach(0.1);
    let o = Options::default();
    let mut hn = h.clone();
    hn[7] = f64::NAN;
    assert_eq!(
        name(solve(&problem(&hn, ny, nx, Boundary::Free), d, &o, None)),
        "heights"
    );
    assert_eq!(
        name(solve(
            &problem(&h[1..], ny, nx, Boundary::Free),
            d,
            &o,
            None
        )),
        "heights"
    );
    assert_eq!(
        name(solve(&problem(&[], 0, 5, Boundary::Free), d, &o, None)),
        "heights"
    );
    assert_eq!(name(solve(&Problem { dx: 0.0, ..pr }, d, &o, None)), "dx");
    assert_eq!(
        name(solve(&Problem { e_star: -1.0, ..pr }, d, &o, None)),
        "e_star"
    );
    assert_eq!(
        name(solve(
            &Problem {
                e_star: f64::NAN,
                ..pr
            },
            d,
            &o,
            None
        )),
        "e_star"
    );
    assert_eq!(
        name(solve(&pr, Control::Approach(-0.1), &o, None)),
        "approach"
    );
    assert_eq!(
        name(solve(&pr, Control::Approach(f64::INFINITY), &o, None)),
        "approach"
    );
    assert_eq!(
        name(solve(&pr, Control::MeanPressure(0.0), &o, None)),
        "mean_pressure"
    );
    assert_eq!(
        name(solve(&pr, Control::MeanPressure(f64::NAN), &o, None)),
        "mean_pressure"
    );
    assert_eq!(name(solve(&pr, d, &opts(0.0), None)), "tol");
    assert_eq!(name(solve(&pr, d, &opts(f64::NAN), None)), "tol");
    let short = vec![0.0; 3];
    assert_eq!(name(solve(&pr, d, &o, Some(&short))), "initial_pressure");
    let mut nan_init = vec![0.0; ny * nx];
    nan_init[0] = f64::NAN;
    assert_eq!(name(solve(&pr, d, &o, Some(&nan_init))), "initial_pressure");
    let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
    assert_eq!(name(solve_with_operator(&op, &pr, d, &o, None)), "operator");

    // Memory limit, iteration cap, interruption.
    let small = Options {
        memory_limit: Some(1000),
        ..Options::default()
    };
    assert!(matches!(
        solve(&pr, d, &small, None),
        Err(Error::TooLarge { .. })
    ));
    let capped = Options {
        max_iter: Some(1),
        ..opts(1e-14)
    };
    match solve(&pr, Control::Approach(0.3), &capped, None) {
        Err(Error::NotConverged {
            iterations, what, ..
        }) => {
            assert_eq!(iterations, 1);
            assert_eq!(what, "Polonsky–Keer");
        }
        other => panic!("{other:?}"),
    }
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let stop = || {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        true
    };
    let interrupt = Options {
        should_stop: Some(&stop),
        ..Options::default()
    };
    assert_eq!(
        solve(&pr, Control::Approach(0.3), &interrupt, None).unwrap_err(),
        Error::Interrupted
    );
    assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 1);
}

#[test]
fn caller_kernel_table_and_incremental_finish() {
    let (ny, nx) = (48usize, 45usize);
    let h = rough(ny, nx, 21);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = approach_range(&h, boundary);
        let (op, table) = match boundary {
            Boundary::Free => {
                let k = Kernel::new(ny, nx, pr.dx, pr.e_star);
                (Operator::free(&k), k.table)
            }
            Boundary::Periodic => {
                let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
                let mut e0 = vec![0.0; ny * nx];
                e0[0] = 1.0;
                let mut t = vec![0.0; ny * nx];
                op.apply(&e0, &mut t);
                (op, t)
            }
        };
        for f in [0.2, 0.5] {
            let control = Control::Approach(f * top);
            let o = opts(1e-12);
            let a = solve_with_operator(&op, &pr, control, &o, None).unwrap();
            let b = solve_with_kernel(&op, Some(&table), &pr, control, &o, None).unwrap();
            let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
            let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
            assert_eq!(ca, cb, "{boundary:?} {f}");
            assert!(max_rel(&a.pressure, &b.pressure) < 1e-8);
            assert!(b.kkt <= 1e-12);
            // The given table spares the product that builds it (when the sparse path ran).
            assert!(
                b.fft_products <= a.fft_products,
                "{} vs {}",
                b.fft_products,
                a.fft_products
            );
            // An incremental finish stops on the updated state: the same contact set at a
            // looser tolerance, no confirming product, no displacement unless fresh.
            let loose = opts(1e-6);
            let c = solve_level(&pr, control, &loose, None, Finish::Confirmed, 0, None).unwrap();
            let d = solve_level(&pr, control, &loose, None, Finish::Incremental, 0, None).unwrap();
            assert!(d.fft_products <= c.fft_products);
            assert_eq!(c.iterations, d.iterations);
            assert_eq!(c.pressure, d.pressure);
            assert!(d.displacement.is_empty() || d.displacement == c.displacement);
        }
        let short = vec![0.0; ny * nx - 1];
        assert!(solve_with_kernel(
            &op,
            Some(&short),
            &pr,
            Control::Approach(0.1),
            &opts(1e-8),
            None
        )
        .is_err());
    }
}
