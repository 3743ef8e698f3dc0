//! Every path to the answer reaches the same minimiser: chord and rescaled load steps, the
//! coarse start, the preconditioner, warm starts.
use super::*;

#[test]
fn chord_steps_reach_the_exact_minimiser() {
    // From p = 0 the early iterations truncate or add a large part of the contact set at
    // once, so they are chord steps (one product of the whole change); the answer must
    // still be the exact minimiser, found here by a dense projected Gauss–Seidel and
    // Cholesky on its contact set.
    let (ny, nx) = (24usize, 24usize);
    let (mut chords, mut load_chords) = (0, 0);
    for seed in [5u64, 6] {
        let h = rough(ny, nx, seed);
        let pr = problem(&h, ny, nx, Boundary::Free);
        let ker = Kernel::new(ny, nx, pr.dx, pr.e_star);
        let n = ny * nx;
        let c: Vec<f64> = (0..n * n).map(|k| ker.coeff(k / n, k % n)).collect();
        let (hmax, hmin, _) = height_stats(&h);
        for frac in [0.3, 0.6, 1.0] {
            let delta = frac * (hmax - hmin);
            let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
            let exact = dense_reference(&c, &b);
            for precondition in [true, false] {
                let o = Options {
                    precondition,
                    ..opts(1e-12)
                };
                let s = solve(&pr, Control::Approach(delta), &o, None).unwrap();
                chords += s.chord_steps;
                let regular = Options {
                    chord_steps: false,
                    ..o
                };
                let r = solve(&pr, Control::Approach(delta), &regular, None).unwrap();
                assert_eq!(r.chord_steps, 0);
                assert!(max_rel(&r.pressure, &exact) < 1e-8);
                assert!(s.chord_steps < s.iterations);
                let ca: Vec<bool> = s.pressure.iter().map(|&p| p > 0.0).collect();
                let ce: Vec<bool> = exact.iter().map(|&p| p > 0.0).collect();
                assert_eq!(ca, ce, "seed {seed} Δ*={frac} pre {precondition}");
                let e = max_rel(&s.pressure, &exact);
                assert!(e < 1e-8, "seed {seed} Δ*={frac}: rel err {e}");
                assert!(s.kkt <= 1e-12);
                // Load control with and without chord steps: the same minimiser.
                let l = solve(&pr, Control::MeanPressure(s.mean_pressure), &o, None).unwrap();
                load_chords += l.chord_steps;
                assert!(l.chord_steps < l.iterations.max(1));
                let e = max_rel(&l.pressure, &exact);
                assert!(e < 1e-8, "load, seed {seed} Δ*={frac}: rel err {e}");
                let cl: Vec<bool> = l.pressure.iter().map(|&p| p > 0.0).collect();
                assert_eq!(cl, ce, "load, seed {seed} Δ*={frac} pre {precondition}");
                let lr =
                    solve(&pr, Control::MeanPressure(s.mean_pressure), &regular, None).unwrap();
                assert_eq!(lr.chord_steps, 0);
                assert!(max_rel(&lr.pressure, &exact) < 1e-8);
            }
        }
    }
    assert!(chords > 0, "no chord step was taken");
    assert!(load_chords > 0, "no load-controlled chord step was taken");
}

#[test]
fn rescaled_load_steps_reach_the_exact_minimiser() {
    // Displacement control from a start with pressure takes load-controlled steps and scales
    // `p` to the imposed approach after each: the answer must still be the exact minimiser
    // at that approach (dense projected Gauss–Seidel and Cholesky on its contact set), with
    // the approach reported exactly as given. Warm starts of too little and too much load
    // and the wrong shape, preconditioned or not, and the plain steps from the same start.
    let (ny, nx) = (24usize, 24usize);
    let n = ny * nx;
    for seed in [7u64, 8] {
        let h = rough(ny, nx, seed);
        let pr = problem(&h, ny, nx, Boundary::Free);
        let ker = Kernel::new(ny, nx, pr.dx, pr.e_star);
        let c: Vec<f64> = (0..n * n).map(|k| ker.coeff(k / n, k % n)).collect();
        let (hmax, hmin, _) = height_stats(&h);
        for frac in [0.2, 0.5, 0.9] {
            let delta = frac * (hmax - hmin);
            let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
            let exact = dense_reference(&c, &b);
            let ce: Vec<bool> = exact.iter().map(|&p| p > 0.0).collect();
            let pmax = exact.iter().cloned().fold(0.0, f64::max);
            let w = lcg(seed + 100, n);
            for scale in [0.5, 1.7] {
                let p0: Vec<f64> = exact
                    .iter()
                    .zip(&w)
                    .map(|(&p, &r)| scale * (p + 0.2 * r * pmax))
                    .collect();
                for precondition in [true, false] {
                    let o = Options {
                        precondition,
                        ..opts(1e-12)
                    };
                    let what = format!("seed {seed} Δ*={frac} start ×{scale} pre {precondition}");
                    let s = solve(&pr, Control::Approach(delta), &o, Some(&p0))
                        .unwrap_or_else(|e| panic!("{what}: {e:?}"));
                    assert_eq!(s.approach, delta, "{what}");
                    assert!(s.kkt <= 1e-12, "{what}: kkt {}", s.kkt);
                    let e = max_rel(&s.pressure, &exact);
                    assert!(e < 1e-8, "{what}: rel err {e}");
                    let cs: Vec<bool> = s.pressure.iter().map(|&p| p > 0.0).collect();
                    assert_eq!(cs, ce, "{what}");
                    let plain = Options {
                        rescaled_steps: false,
                        ..o
                    };
                    let r = solve(&pr, Control::Approach(delta), &plain, Some(&p0)).unwrap();
                    let e = max_rel(&r.pressure, &exact);
                    assert!(e < 1e-8, "{what}: plain steps, rel err {e}");
                }
            }
        }
    }
}

#[test]
fn rescaled_load_steps_from_the_coarse_start() {
    // On free grids with a coarse start (≥ 64 points a side) every cold displacement solve
    // takes rescaled load steps: the same minimiser as the plain steps, found independently.
    // Periodic surfaces keep the plain steps: the option changes no bit there.
    let (ny, nx) = (80usize, 72usize);
    let plain = Options {
        rescaled_steps: false,
        ..opts(1e-12)
    };
    for seed in [3u64, 4] {
        let h = rough(ny, nx, seed);
        let (hmax, hmin, hsum) = height_stats(&h);
        let pr = problem(&h, ny, nx, Boundary::Free);
        for frac in [0.1, 0.4, 0.8] {
            let delta = frac * (hmax - hmin);
            let s = solve(&pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
            let r = solve(&pr, Control::Approach(delta), &plain, None).unwrap();
            let what = format!("seed {seed} Δ*={frac}");
            assert_ne!(s.iterations, 0, "{what}");
            assert_eq!(s.approach, delta, "{what}");
            assert!(s.kkt <= 1e-12 && r.kkt <= 1e-12, "{what}");
            let cs: Vec<bool> = s.pressure.iter().map(|&p| p > 0.0).collect();
            let cr: Vec<bool> = r.pressure.iter().map(|&p| p > 0.0).collect();
            assert_eq!(cs, cr, "{what}");
            let e = max_rel(&s.pressure, &r.pressure);
            assert!(e < 1e-8, "{what}: rel diff {e}");
            // The certificate recomputed from the returned fields.
            let k = kkt_certificate(&s.pressure, &s.gap, (hmax - hmin).max(delta));
            assert!(k <= 1.001e-12, "{what}: kkt {k}");
        }
        let pr = problem(&h, ny, nx, Boundary::Periodic);
        let delta = 0.4 * (hmax - hsum / (ny * nx) as f64);
        let s = solve(&pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
        let r = solve(&pr, Control::Approach(delta), &plain, None).unwrap();
        assert_eq!(s.pressure, r.pressure, "periodic, seed {seed}");
        assert_eq!(s.iterations, r.iterations, "periodic, seed {seed}");
    }
}

#[test]
fn preconditioned_and_plain_reach_the_same_minimiser() {
    // Larger than the dense tests, so the preconditioned conjugate steps run for many
    // iterations; both iterations must land on the same contact set and pressures.
    let (ny, nx) = (48usize, 40usize);
    let h = rough(ny, nx, 7);
    let mut used = 0;
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = approach_range(&h, boundary);
        for frac in [0.2, 0.5, 0.9] {
            let delta = frac * top;
            let plain = Options {
                precondition: false,
                ..opts(1e-12)
            };
            let a = solve(&pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
            let b = solve(&pr, Control::Approach(delta), &plain, None).unwrap();
            used += a.preconditioner_products;
            assert_eq!(b.preconditioner_products, 0);
            let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
            let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
            assert_eq!(ca, cb, "{boundary:?} Δ*={frac}");
            let e = max_rel(&a.pressure, &b.pressure);
            assert!(e < 1e-8, "{boundary:?} Δ*={frac}: rel diff {e}");
            assert!(a.kkt <= 1e-12 && b.kkt <= 1e-12);
        }
    }
    assert!(used > 0, "no preconditioned step was taken");
}

#[test]
fn coarse_start_and_cold_start_reach_the_same_minimiser() {
    // Large enough for two coarse levels (97 → 49 → 25 per side).
    let (ny, nx) = (97usize, 100usize);
    let h = rough(ny, nx, 13);
    let (hmax, hmin, _) = height_stats(&h);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = approach_range(&h, boundary);
        let mut controls: Vec<Control> = [0.1, 0.3, 0.6]
            .iter()
            .map(|f| Control::Approach(f * top))
            .collect();
        let cold = Options {
            coarse_start: false,
            ..opts(1e-12)
        };
        let mid = solve(&pr, Control::Approach(0.3 * top), &cold, None).unwrap();
        controls.push(Control::MeanPressure(mid.mean_pressure));
        for control in controls {
            let a = solve(&pr, control, &opts(1e-12), None).unwrap();
            let b = solve(&pr, control, &cold, None).unwrap();
            assert_eq!(b.coarse, CoarseCost::default());
            // Two levels, or one when nothing touches on the coarsest (its highest node
            // is lower than the fine summit).
            let levels = a.coarse.levels;
            assert!(
                (1..=2).contains(&levels),
                "{boundary:?} {control:?}: {levels}"
            );
            assert!(a.coarse.fft_products > 0);
            let ratio = a.coarse.fft_products_fine_equivalent / a.coarse.fft_products as f64;
            assert!(ratio > 0.0 && ratio < 0.26, "{ratio}");
            let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
            let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
            assert_eq!(ca, cb, "{boundary:?} {control:?}");
            let e = max_rel(&a.pressure, &b.pressure);
            assert!(e < 1e-8, "{boundary:?} {control:?}: rel diff {e}");
            assert!(a.kkt <= 1e-12 && b.kkt <= 1e-12);
            assert!((a.approach - b.approach).abs() < 1e-9 * (hmax - hmin));
        }
    }
    // A warm start or a small grid skips the coarse levels.
    let pr = problem(&h, ny, nx, Boundary::Free);
    let first = solve(&pr, Control::Approach(0.1), &Options::default(), None).unwrap();
    let s = solve(
        &pr,
        Control::Approach(0.2),
        &Options::default(),
        Some(&first.pressure),
    )
    .unwrap();
    assert_eq!(s.coarse, CoarseCost::default());
    let small = rough(40, 70, 3);
    let s = solve(
        &problem(&small, 40, 70, Boundary::Free),
        Control::Approach(0.1),
        &Options::default(),
        None,
    )
    .unwrap();
    assert_eq!(s.coarse.levels, 0);
}

#[test]
fn warm_start_agrees_with_cold() {
    let (ny, nx) = (64usize, 64usize);
    let h = rough(ny, nx, 33);
    let (hmax, hmin, _) = height_stats(&h);
    let hs = hmax - hmin;
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let first = solve(&pr, Control::Approach(0.2 * hs), &Options::default(), None).unwrap();
        for control in [
            Control::Approach(0.3 * hs),
            Control::MeanPressure(1.5 * first.mean_pressure),
        ] {
            let cold = solve(&pr, control, &Options::default(), None).unwrap();
            let warm = solve(&pr, control, &Options::default(), Some(&first.pressure)).unwrap();
            assert!(warm.kkt <= DEFAULT_TOL && cold.kkt <= DEFAULT_TOL);
            // A gap residual ε·h_s moves p by about ε·h_s/C_00 relative to p ~ Δ/C_00.
            assert!(
                max_rel(&warm.pressure, &cold.pressure) < 1e-7,
                "{boundary:?} {control:?}: {}",
                max_rel(&warm.pressure, &cold.pressure)
            );
            assert!((warm.approach - cold.approach).abs() < 1e-8 * hs);
        }
    }
}
