//! Tests of the capped solver against independent references.

use super::*;
use crate::contact::kkt::kkt_certificate_capped;
use crate::contact::polonsky_keer as pk;
use crate::elastic::kernel::Kernel;
use crate::elastic::operator::dense_apply;
use crate::grid::Boundary;

fn rough(ny: usize, nx: usize, seed: u64) -> Vec<f64> {
    let phases = crate::test_support::lcg(seed, 4);
    let mut h = vec![0.0; ny * nx];
    for k in 1..5 {
        let ph = phases[k - 1] * std::f64::consts::TAU;
        for i in 0..ny {
            for j in 0..nx {
                let x = (i as f64 / ny as f64 + j as f64 / nx as f64 * 0.7) * k as f64;
                h[i * nx + j] += (std::f64::consts::TAU * x + ph).sin() / k as f64;
            }
        }
    }
    h
}

fn opts(hardness: f64) -> Options<'static> {
    Options {
        hardness: Some(hardness),
        ..Options::default()
    }
}

/// Projected Gauss–Seidel on the dense matrix: the box QP solved point by point, an
/// independent oracle for small grids.
fn dense_box_qp(c: &[f64], b: &[f64], cap: f64) -> Vec<f64> {
    let n = b.len();
    let mut p = vec![0.0; n];
    for _ in 0..200_000 {
        let mut change = 0.0f64;
        for i in 0..n {
            let mut s = b[i];
            for j in 0..n {
                if j != i {
                    s -= c[i * n + j] * p[j];
                }
            }
            let v = (s / c[i * n + i]).clamp(0.0, cap);
            change = change.max((v - p[i]).abs());
            p[i] = v;
        }
        if change < 1e-15 * cap {
            break;
        }
    }
    p
}

#[test]
fn capped_matches_projected_gauss_seidel() {
    let (ny, nx) = (8, 9);
    let h = rough(ny, nx, 3);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let problem = Problem {
            heights: &h,
            ny,
            nx,
            dx: 0.1,
            e_star: 1.0,
            boundary,
        };
        let kernel = match boundary {
            Boundary::Free => Kernel::new(ny, nx, 0.1, 1.0),
            Boundary::Periodic => {
                let op = Operator::periodic(ny, nx, 0.1, 1.0);
                let mut e0 = vec![0.0; ny * nx];
                e0[0] = 1.0;
                let mut col = vec![0.0; ny * nx];
                op.apply(&e0, &mut col);
                Kernel::from_table(ny, nx, 0.1, 1.0, col)
            }
        };
        let n = ny * nx;
        let mut c = vec![0.0; n * n];
        for j in 0..n {
            let mut e = vec![0.0; n];
            e[j] = 1.0;
            let col = dense_apply(&kernel, &e);
            for i in 0..n {
                c[i * n + j] = col[i];
            }
        }
        let hmax = h.iter().cloned().fold(f64::MIN, f64::max);
        let delta = 0.8;
        let b: Vec<f64> = h.iter().map(|&hi| delta - (hmax - hi)).collect();
        let cap = 0.05;
        let want = dense_box_qp(&c, &b, cap);
        let got = solve(&problem, Control::Approach(delta), &opts(cap), None).unwrap();
        let err = got
            .pressure
            .iter()
            .zip(&want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-9 * cap, "{boundary:?}: {err}");
        assert!(got.plastic_points > 0);
        assert!(got.pressure.iter().all(|&v| (0.0..=cap).contains(&v)));
        let k = kkt_certificate_capped(&got.pressure, &got.gap, cap, 1.0);
        assert!(k <= 1e-10, "{k}");
    }
}

#[test]
fn load_control_meets_the_load_and_the_approach_solution() {
    let (ny, nx) = (12, 10);
    let h = rough(ny, nx, 5);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let problem = Problem {
            heights: &h,
            ny,
            nx,
            dx: 0.1,
            e_star: 1.0,
            boundary,
        };
        let cap = 0.08;
        let load = solve(&problem, Control::MeanPressure(0.02), &opts(cap), None).unwrap();
        assert!((load.mean_pressure - 0.02).abs() <= 1e-9 * 0.02);
        assert!(load.plastic_points > 0);
        let disp = solve(&problem, Control::Approach(load.approach), &opts(cap), None).unwrap();
        let err = load
            .pressure
            .iter()
            .zip(&disp.pressure)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-7 * cap, "{err}");
    }
}

#[test]
fn full_plastic_and_refusals() {
    let (ny, nx) = (6, 7);
    let h = rough(ny, nx, 1);
    let problem = Problem {
        heights: &h,
        ny,
        nx,
        dx: 0.1,
        e_star: 1.0,
        boundary: Boundary::Free,
    };
    let s = solve(&problem, Control::MeanPressure(0.3), &opts(0.3), None).unwrap();
    assert!(s.pressure.iter().all(|&v| v == 0.3));
    assert!(s.gap.iter().all(|&g| g <= 1e-12));
    assert_eq!(s.plastic_points, ny * nx);
    let e = solve(&problem, Control::MeanPressure(0.31), &opts(0.3), None).unwrap_err();
    assert!(e.to_string().contains("hardness"), "{e}");
    for bad in [0.0, -1.0, f64::NAN] {
        let e = solve(&problem, Control::Approach(0.5), &opts(bad), None).unwrap_err();
        assert!(e.to_string().starts_with("hardness"), "{e}");
    }
}

#[test]
fn infinite_hardness_is_the_elastic_solve_bit_for_bit() {
    let (ny, nx) = (70, 66);
    let h = rough(ny, nx, 7);
    let problem = Problem {
        heights: &h,
        ny,
        nx,
        dx: 0.1,
        e_star: 1.0,
        boundary: Boundary::Free,
    };
    let a = pk::solve(&problem, Control::Approach(0.7), &Options::default(), None).unwrap();
    let b = pk::solve(&problem, Control::Approach(0.7), &opts(f64::INFINITY), None).unwrap();
    assert_eq!(a.pressure, b.pressure);
    assert_eq!(a.iterations, b.iterations);
    // A cap above every elastic pressure gives the elastic contact set.
    let pmax = a.pressure.iter().cloned().fold(0.0, f64::max);
    let c = solve(&problem, Control::Approach(0.7), &opts(2.0 * pmax), None).unwrap();
    assert_eq!(c.plastic_points, 0);
    let err = a
        .pressure
        .iter()
        .zip(&c.pressure)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-8 * pmax, "{err}");
}

#[test]
fn preconditioned_and_plain_solves_agree() {
    let (ny, nx) = (70, 66);
    let h = rough(ny, nx, 11);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let problem = Problem {
            heights: &h,
            ny,
            nx,
            dx: 0.1,
            e_star: 1.0,
            boundary,
        };
        for (control, cap) in [
            (Control::Approach(0.4), 0.05),
            (Control::Approach(0.8), 0.1),
            (Control::MeanPressure(0.01), 0.04),
        ] {
            let plain = Options {
                precondition: false,
                ..opts(cap)
            };
            let a = solve(&problem, control, &plain, None).unwrap();
            let b = solve(&problem, control, &opts(cap), None).unwrap();
            let what = format!("{boundary:?} {control:?} H = {cap}");
            assert_eq!(a.preconditioner_products, 0, "{what}");
            assert!(b.preconditioner_products > 0, "{what}");
            assert!(b.plastic_points > 0, "{what}");
            assert_eq!(a.contact_points, b.contact_points, "{what}");
            assert_eq!(a.plastic_points, b.plastic_points, "{what}");
            for (x, y) in a.pressure.iter().zip(&b.pressure) {
                assert_eq!(*x > 0.0, *y > 0.0, "{what}: contact sets differ");
                assert_eq!(*x >= cap, *y >= cap, "{what}: plastic sets differ");
                assert!((x - y).abs() <= 1e-8 * cap, "{what}: {x} vs {y}");
            }
            let k = kkt_certificate_capped(&b.pressure, &b.gap, cap, 1.0);
            assert!(k <= 1e-10, "{what}: {k}");
        }
    }
}
