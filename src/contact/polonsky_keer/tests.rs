//! Tests of the Polonsky–Keer solver against independent references.

use super::driver::height_stats;
use super::sparse::add_sparse;
use super::*;
use crate::contact::kkt::kkt_certificate;
use crate::elastic::kernel::love_displacement;
use crate::elastic::operator::dense_apply;
use std::f64::consts::PI;

use crate::test_support::lcg;

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

fn max_rel(a: &[f64], b: &[f64]) -> f64 {
    let s = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / s
}

#[test]
fn matches_dense_exact_solution_free() {
    for &(ny, nx, seed) in &[(9usize, 9usize, 1u64), (12, 7, 2), (7, 12, 3)] {
        let h = rough(ny, nx, seed);
        let pr = problem(&h, ny, nx, Boundary::Free);
        let ker = Kernel::new(ny, nx, pr.dx, pr.e_star);
        let n = ny * nx;
        let c: Vec<f64> = (0..n * n).map(|k| ker.coeff(k / n, k % n)).collect();
        let (hmax, hmin, _) = height_stats(&h);
        for frac in [0.1, 0.4, 0.8, 1.5] {
            let delta = frac * (hmax - hmin);
            let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
            let exact = dense_reference(&c, &b);
            let s = solve(&pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
            let e = max_rel(&s.pressure, &exact);
            assert!(e < 1e-8, "{ny}x{nx} Δ*={frac}: rel err {e}");
            assert!(s.kkt <= 1e-12);
            // Reported gap is the documented formula with a fresh u = C p.
            let u = dense_apply(&ker, &s.pressure);
            for i in 0..n {
                let g = hmax - delta - h[i] + u[i];
                assert!((g - s.gap[i]).abs() < 1e-12 * (hmax - hmin));
            }
            // Load control with the same mean pressure reaches the same state.
            let l = solve(
                &pr,
                Control::MeanPressure(s.mean_pressure),
                &opts(1e-12),
                None,
            )
            .unwrap();
            assert!(max_rel(&l.pressure, &exact) < 1e-8);
            assert!(
                (l.approach - delta).abs() < 1e-9 * (hmax - hmin),
                "{} vs {delta}",
                l.approach
            );
        }
    }
}

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
    let (hmax, hmin, hsum) = height_stats(&h);
    let mut used = 0;
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = match boundary {
            Boundary::Free => hmax - hmin,
            Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
        };
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
    let (hmax, hmin, hsum) = height_stats(&h);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = match boundary {
            Boundary::Free => hmax - hmin,
            Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
        };
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
fn matches_dense_exact_solution_periodic() {
    let (ny, nx) = (8usize, 10usize);
    let h = rough(ny, nx, 11);
    let pr = problem(&h, ny, nx, Boundary::Periodic);
    let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
    let c = dense_matrix_from_operator(&op);
    let (hmax, hmin, hsum) = height_stats(&h);
    let limit = hmax - hsum / (ny * nx) as f64;
    for frac in [0.2, 0.5, 0.9] {
        let delta = frac * limit;
        let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
        let exact = dense_reference(&c, &b);
        let s =
            solve_with_operator(&op, &pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
        let e = max_rel(&s.pressure, &exact);
        assert!(e < 1e-8, "Δ={frac}·limit: rel err {e}");
        let l = solve_with_operator(
            &op,
            &pr,
            Control::MeanPressure(s.mean_pressure),
            &opts(1e-12),
            None,
        )
        .unwrap();
        assert!(max_rel(&l.pressure, &exact) < 1e-8);
        assert!((l.approach - delta).abs() < 1e-9 * (hmax - hmin));
    }
}

#[test]
fn certificate_meets_tolerance_and_is_honest() {
    let (ny, nx) = (40usize, 33usize);
    let h = rough(ny, nx, 5);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        for (control, tol) in [
            (Control::Approach(0.05), DEFAULT_TOL),
            (Control::Approach(0.2), 1e-8),
            (Control::MeanPressure(0.02), DEFAULT_TOL),
        ] {
            let s = solve(&pr, control, &opts(tol), None).unwrap();
            assert!(s.kkt <= tol, "{boundary:?} {control:?}: {}", s.kkt);
            let (hmax, hmin, _) = height_stats(&h);
            // The documented scale: max(h_s, Δ), or max(h_s, |Δ|, p̄·C_00) under a load.
            let c00 = love_displacement(0.0, 0.0, pr.dx, pr.e_star);
            let scale = match control {
                Control::Approach(d) => (hmax - hmin).max(d),
                Control::MeanPressure(m) => (hmax - hmin).max(s.approach.abs()).max(m * c00),
            };
            let again = kkt_certificate(&s.pressure, &s.gap, scale);
            assert_eq!(again, s.kkt);
            assert!(s.pressure.iter().all(|&v| v >= 0.0));
            assert_eq!(
                s.contact_points,
                s.pressure.iter().filter(|&&v| v > 0.0).count()
            );
            let sum: f64 = s.pressure.iter().sum();
            assert!((s.load - sum * pr.dx * pr.dx).abs() <= 1e-12 * s.load);
            // Δ = max h − h_i + u_i − g_i everywhere.
            for ((&hi, &ui), &gi) in h.iter().zip(&s.displacement).zip(&s.gap) {
                let d = hmax - hi + ui - gi;
                assert!((d - s.approach).abs() < 1e-12 * (hmax - hmin));
            }
        }
    }
}

#[test]
fn load_control_reaches_displacement_state() {
    let (ny, nx) = (64usize, 48usize);
    let h = rough(ny, nx, 8);
    let (hmax, hmin, _) = height_stats(&h);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let delta = 0.3 * (hmax - hmin);
        let d = solve(&pr, Control::Approach(delta), &opts(1e-12), None).unwrap();
        let l = solve(
            &pr,
            Control::MeanPressure(d.mean_pressure),
            &opts(1e-12),
            None,
        )
        .unwrap();
        assert!(max_rel(&l.pressure, &d.pressure) < 1e-8);
        assert!((l.approach - delta).abs() < 1e-9 * (hmax - hmin));
        assert!((l.mean_pressure - d.mean_pressure).abs() < 1e-12 * d.mean_pressure);
    }
}

#[test]
fn periodic_westergaard() {
    // h = A cos(2πx/λ) along axis 1, uniform along axis 0: the contact half-width a obeys
    // p̄/p* = sin²(πa/λ), p* = π E* A/λ, and full contact starts at p̄ = p*.
    let (ny, nx) = (8usize, 512usize);
    let (dx, e_star, amp) = (1.0 / 512.0, 2.0, 0.01);
    let lambda = nx as f64 * dx;
    let h: Vec<f64> = (0..ny * nx)
        .map(|k| amp * (2.0 * PI * (k % nx) as f64 * dx / lambda).cos())
        .collect();
    let pr = Problem {
        heights: &h,
        ny,
        nx,
        dx,
        e_star,
        boundary: Boundary::Periodic,
    };
    let p_star = PI * e_star * amp / lambda;
    for ratio in [0.1, 0.25, 0.5, 0.75, 0.9] {
        let s = solve(
            &pr,
            Control::MeanPressure(ratio * p_star),
            &opts(1e-11),
            None,
        )
        .unwrap();
        assert_eq!(s.contact_points % ny, 0);
        let a = (s.contact_points / ny) as f64 * dx / 2.0;
        let a_exact = lambda / PI * ratio.sqrt().asin();
        let e = (a - a_exact).abs() / a_exact;
        assert!(e < 0.01, "p̄/p* = {ratio}: a = {a}, exact {a_exact} ({e})");
    }
    // Full contact starts at p*: just below, a gap remains; just above, none.
    let below = solve(
        &pr,
        Control::MeanPressure(0.99 * p_star),
        &opts(1e-11),
        None,
    )
    .unwrap();
    assert!(below.contact_points < ny * nx);
    let above = solve(
        &pr,
        Control::MeanPressure(1.01 * p_star),
        &opts(1e-11),
        None,
    )
    .unwrap();
    assert_eq!(above.contact_points, ny * nx);
    assert!((above.approach - amp).abs() < 1e-9 * amp);
    // Displacement control at the limit Δ = max h − mean h returns the full-contact
    // state at its onset, p̄ = p*; beyond it is an error, not a hang.
    let s = solve(&pr, Control::Approach(amp), &opts(1e-11), None).unwrap();
    assert!(s.kkt <= 1e-11);
    assert!(
        (s.mean_pressure - p_star).abs() < 1e-6 * p_star,
        "{} vs {p_star}",
        s.mean_pressure
    );
    // Near the trough p and g both vanish; the certificate bounds −g and g on I_c, and the
    // few free trough points are left with gaps of the same order.
    assert!(s.gap.iter().all(|g| g.abs() <= 1e-9 * 2.0 * amp));
    match solve(&pr, Control::Approach(1.01 * amp), &opts(1e-11), None) {
        Err(Error::InvalidArgument { name, message }) => {
            assert_eq!(name, "approach");
            assert!(message.contains("0.01"), "{message}");
        }
        other => panic!("{other:?}"),
    }
}

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
fn caller_kernel_table_and_incremental_finish() {
    let (ny, nx) = (48usize, 45usize);
    let h = rough(ny, nx, 21);
    let (hmax, hmin, hsum) = height_stats(&h);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let pr = problem(&h, ny, nx, boundary);
        let top = match boundary {
            Boundary::Free => hmax - hmin,
            Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
        };
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
