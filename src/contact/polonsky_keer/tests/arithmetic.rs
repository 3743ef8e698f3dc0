//! The arithmetic: sparse corrections equal the operator, single-precision products reach
//! the same minimiser, and one and two threads give the same bits.
use super::*;

#[test]
fn one_and_two_threads_agree() {
    let (ny, nx) = (96usize, 100usize);
    let h = rough(ny, nx, 21);
    let pr = problem(&h, ny, nx, Boundary::Free);
    let run = |threads: usize, control: Control| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| solve(&pr, control, &Options::default(), None).unwrap())
    };
    for control in [Control::Approach(0.1), Control::MeanPressure(0.01)] {
        let a = run(1, control);
        let b = run(2, control);
        assert_eq!(a.iterations, b.iterations);
        assert!(max_rel(&a.pressure, &b.pressure) <= 1e-12);
        assert!(max_rel(&a.gap, &b.gap) <= 1e-12);
        assert!((a.approach - b.approach).abs() <= 1e-12 * a.approach.abs());
    }
}

#[test]
fn sparse_correction_equals_operator() {
    // Chunks of CHUNK points cut rows in the middle on this grid.
    let (ny, nx) = (70usize, 93usize);
    let n = ny * nx;
    for periodic in [false, true] {
        let op = if periodic {
            Operator::periodic(ny, nx, 0.3, 2.0)
        } else {
            Operator::free(&Kernel::new(ny, nx, 0.3, 2.0))
        };
        let mut e0 = vec![0.0; n];
        e0[0] = 1.0;
        let mut table = vec![0.0; n];
        op.apply(&e0, &mut table);
        let idx = [
            0usize,
            5,
            nx - 1,
            nx,
            2 * nx + 17,
            4095,
            4096,
            n / 2,
            n - nx,
            n - 1,
        ];
        let vals = lcg(77, idx.len());
        let changes: Vec<(usize, f64)> = idx.iter().copied().zip(vals).collect();
        let mut d = vec![0.0; n];
        for &(b, v) in &changes {
            d[b] = v;
        }
        let mut want = vec![0.0; n];
        op.apply(&d, &mut want);
        let mut got = vec![0.0; n];
        for (c, out) in got.chunks_mut(CHUNK).enumerate() {
            add_sparse(out, c * CHUNK, &changes, &table, ny, nx, periodic);
        }
        let e = max_rel(&got, &want);
        assert!(e < 1e-12, "periodic={periodic}: {e}");
        if !periodic {
            // The Love kernel table, which free solves use instead of the product C e_0,
            // against the same FFT oracle.
            let love = Kernel::new(ny, nx, 0.3, 2.0).table;
            let mut got = vec![0.0; n];
            for (c, out) in got.chunks_mut(CHUNK).enumerate() {
                add_sparse(out, c * CHUNK, &changes, &love, ny, nx, false);
            }
            let e = max_rel(&got, &want);
            assert!(e < 1e-12, "Love table: {e}");
            // The oracle catches a table off by one column.
            let mut shifted = love.clone();
            for i in 0..ny {
                for j in 0..nx - 1 {
                    shifted[i * nx + j] = love[i * nx + j + 1];
                }
            }
            let mut bad = vec![0.0; n];
            for (c, out) in bad.chunks_mut(CHUNK).enumerate() {
                add_sparse(out, c * CHUNK, &changes, &shifted, ny, nx, false);
            }
            assert!(max_rel(&bad, &want) > 1e-3);
        }
    }
}

#[test]
fn single_precision_early_products_reach_the_same_minimiser() {
    // f32 products while the certificate is above the switch level, then f64: the same
    // contact set as a solve in f64 throughout, certificates below tol, loads and gaps within
    // the certificates' bound; the returned gap is the f64 gap of the returned pressure
    // (recomputed here with the f64 operator).
    let tol = 1e-10;
    for (ny, nx, boundary) in [
        (129usize, 129usize, Boundary::Free),
        (144, 160, Boundary::Periodic),
    ] {
        let h = rough(ny, nx, 31);
        let (hmax, hmin, _) = height_stats(&h);
        let hs = hmax - hmin;
        let pr = problem(&h, ny, nx, boundary);
        let op = match boundary {
            Boundary::Free => Operator::free(&crate::elastic::kernel::Kernel::new(
                ny, nx, pr.dx, pr.e_star,
            )),
            Boundary::Periodic => Operator::periodic(ny, nx, pr.dx, pr.e_star),
        };
        let double = Options {
            single_precision_above: 0.0,
            ..opts(tol)
        };
        let mut single_used = 0;
        for control in [
            Control::Approach(0.2 * hs),
            Control::Approach(0.5 * hs),
            Control::MeanPressure(0.02),
        ] {
            let a = solve(&pr, control, &opts(tol), None).unwrap();
            let b = solve(&pr, control, &double, None).unwrap();
            assert_eq!(b.single_products, 0);
            single_used += a.single_products;
            assert!(a.single_products < a.fft_products);
            // Below the switch only the fresh products C p are f64 (at the switch, every
            // hundredfold fall of the certificate and the confirmation): the increments C t
            // and the corrections C d of steps that change too many points for direct
            // summation stay f32. Those corrections were fresh f64 products C p before, and
            // made up to 9 f64 products in load control here.
            let double_products = a.fft_products - a.single_products;
            assert!(
                double_products <= 6,
                "{boundary:?} {control:?}: {double_products}"
            );
            assert_same_minimiser(
                &op,
                &h,
                hmax,
                hs,
                &a,
                &b,
                tol,
                &format!("{boundary:?} {control:?}"),
            );
        }
        assert!(single_used > 0, "{boundary:?}: no f32 product was made");
    }
}

#[test]
fn single_precision_products_are_the_same_for_one_and_two_threads() {
    let (ny, nx) = (129usize, 120usize);
    let h = rough(ny, nx, 5);
    let pr = problem(&h, ny, nx, Boundary::Free);
    let run = |threads: usize, control: Control| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| solve(&pr, control, &opts(1e-10), None).unwrap())
    };
    for control in [Control::Approach(0.15), Control::MeanPressure(0.01)] {
        let a = run(1, control);
        let b = run(2, control);
        assert!(a.single_products > 0);
        assert_eq!(
            (a.iterations, a.fft_products, a.single_products),
            (b.iterations, b.fft_products, b.single_products)
        );
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.pressure), bits(&b.pressure));
        assert_eq!(bits(&a.gap), bits(&b.gap));
        assert_eq!(a.approach.to_bits(), b.approach.to_bits());
    }
}

#[test]
fn many_point_corrections_below_the_switch_are_single_precision_increments() {
    // Load control at 513², free: below the switch level, two steps change more points than
    // direct summation takes. Their corrections C d are f32 increments (before, each was a
    // fresh f64 product C p: 6 f64 products in all, now the switch, two hundredfold refreshes
    // and the confirmation). Oracle: the same solve in f64 throughout — the same contact
    // set, certificates below tol, the returned gap equal to the f64 gap of the returned
    // pressure, gaps and approach within the certificates' bound, loads within 1e-9.
    let (n, tol) = (513usize, 1e-10);
    let h = rough(n, n, 31);
    let (hmax, hmin, _) = height_stats(&h);
    let pr = problem(&h, n, n, Boundary::Free);
    let op = Operator::free(&crate::elastic::kernel::Kernel::new(n, n, pr.dx, pr.e_star));
    let double = Options {
        single_precision_above: 0.0,
        ..opts(tol)
    };
    for pbar in [0.02, 0.05] {
        let control = Control::MeanPressure(pbar);
        let a = solve(&pr, control, &opts(tol), None).unwrap();
        let b = solve(&pr, control, &double, None).unwrap();
        let double_products = a.fft_products - a.single_products;
        assert!(double_products <= 4, "p̄ = {pbar}: {double_products}");
        assert_same_minimiser(
            &op,
            &h,
            hmax,
            hmax - hmin,
            &a,
            &b,
            tol,
            &format!("p̄ = {pbar}"),
        );
        assert!((a.load - b.load).abs() <= 1e-9 * b.load, "p̄ = {pbar}");
    }
}
