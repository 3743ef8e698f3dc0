//! The solver against independent references: the dense exact solution of the same
//! problem, Westergaard's periodic wavy contact, an honest KKT certificate, and load control
//! reaching the displacement-controlled state.
use super::*;

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
