use super::*;

/// A smooth bumpy surface (no randomness needed: several incommensurate waves).
fn surface(ny: usize, nx: usize) -> Vec<f64> {
    (0..ny * nx)
        .map(|k| {
            let (i, j) = ((k / nx) as f64, (k % nx) as f64);
            (0.7 * i).sin() * (0.45 * j).cos() + 0.3 * (1.3 * i + 0.9 * j).sin()
        })
        .collect()
}

const LIMIT: u64 = 1 << 30;

fn problem(h: &[f64], ny: usize, nx: usize, boundary: Boundary) -> ContactProblem {
    ContactProblem::try_new(h.to_vec(), ny, nx, 0.5, 2.0, boundary, LIMIT).unwrap()
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

fn pk_direct(
    h: &[f64],
    ny: usize,
    nx: usize,
    boundary: Boundary,
    control: Control,
    initial_pressure: Option<&[f64]>,
) -> Solution {
    let problem = Problem {
        heights: h,
        ny,
        nx,
        dx: 0.5,
        e_star: 2.0,
        boundary,
    };
    let opts = Options {
        memory_limit: Some(LIMIT),
        ..Default::default()
    };
    match boundary {
        // A free solve keeps the Love table it builds its operator from.
        Boundary::Free => pk::solve(&problem, control, &opts, initial_pressure).unwrap(),
        // A ContactProblem hands its periodic kernel table (the product C e_0) to the
        // solver, which otherwise builds it on first use.
        Boundary::Periodic => {
            let (op, column) = periodic_column(ny, nx);
            pk::solve_with_kernel(
                &op,
                Some(&column),
                &problem,
                control,
                &opts,
                initial_pressure,
            )
            .unwrap()
        }
    }
}

/// The periodic operator of the tests and its column `C e_0` (the kernel table).
fn periodic_column(ny: usize, nx: usize) -> (Operator, Vec<f64>) {
    let op = Operator::try_periodic(ny, nx, 0.5, 2.0).unwrap();
    let mut unit = vec![0.0; ny * nx];
    unit[0] = 1.0;
    let mut column = vec![0.0; ny * nx];
    op.apply(&unit, &mut column);
    (op, column)
}

#[allow(clippy::too_many_arguments)]
fn lh_direct(
    h: &[f64],
    ny: usize,
    nx: usize,
    boundary: Boundary,
    approach: f64,
    block: bool,
    factor: &mut Factor,
    start: lh::Start<'_>,
) -> Solution {
    let (kernel, op) = match boundary {
        Boundary::Free => {
            let kernel = Kernel::try_new(ny, nx, 0.5, 2.0).unwrap();
            let op = Operator::try_free(&kernel).unwrap();
            (kernel, op)
        }
        Boundary::Periodic => {
            let (op, column) = periodic_column(ny, nx);
            (Kernel::from_table(ny, nx, 0.5, 2.0, column), op)
        }
    };
    let n = ny * nx;
    let opts = lh::Options {
        tol: pk::DEFAULT_TOL,
        max_iter: 50 * n + 1000,
        pivoting: if block {
            Pivoting::Block
        } else {
            Pivoting::Single
        },
        memory_limit: 0,
    };
    LawsonHanson::new(&kernel, &op, h, factor)
        .solve(approach, start, &opts, &|| false)
        .unwrap()
}

#[test]
fn solve_equals_each_solver_called_directly() {
    let (ny, nx) = (12, 10);
    let h = surface(ny, nx);
    for boundary in [Boundary::Free, Boundary::Periodic] {
        let mut cp = problem(&h, ny, nx, boundary);
        let opts = Options::default();
        for control in [Control::Approach(0.6), Control::MeanPressure(0.05)] {
            let got = cp
                .solve(control, Solver::PolonskyKeer, Start::Cold, &opts)
                .unwrap();
            let want = pk_direct(&h, ny, nx, boundary, control, None);
            assert_eq!(got.solver, Solver::PolonskyKeer);
            assert!(
                same_bits(&got.pressure, &want.pressure),
                "{boundary:?} {control:?}"
            );
            assert!(same_bits(&got.gap, &want.gap));
            assert!(same_bits(&got.displacement, &want.displacement));
            assert_eq!(got.kkt.to_bits(), want.kkt.to_bits());
            assert_eq!(got.approach.to_bits(), want.approach.to_bits());
            assert_eq!(
                (got.iterations, got.fft_products, got.contact_points),
                (want.iterations, want.fft_products, want.contact_points)
            );
        }
        for (solver, block) in [(Solver::ActiveSet, true), (Solver::LawsonHanson, false)] {
            let got = cp
                .solve(Control::Approach(0.6), solver, Start::Cold, &opts)
                .unwrap();
            let mut factor = Factor::new(ny * nx, LIMIT);
            let want = lh_direct(
                &h,
                ny,
                nx,
                boundary,
                0.6,
                block,
                &mut factor,
                lh::Start::Cold,
            );
            assert_eq!(got.solver, solver);
            assert!(
                same_bits(&got.pressure, &want.pressure),
                "{boundary:?} {solver:?}"
            );
            assert!(same_bits(&got.gap, &want.gap));
            assert_eq!(got.kkt.to_bits(), want.kkt.to_bits());
            assert_eq!(got.iterations, want.iterations);
            assert_eq!(got.contact_points, want.contact_points);
            // Both certify the same minimiser as Polonsky–Keer.
            assert!(got.kkt <= pk::DEFAULT_TOL);
        }
    }
}

#[test]
fn warm_starts_are_the_solvers_own() {
    let (ny, nx) = (12, 10);
    let h = surface(ny, nx);
    let opts = Options::default();
    let mut cp = problem(&h, ny, nx, Boundary::Free);
    // Polonsky–Keer from the previous pressure, and from a given field.
    let first = cp
        .solve(
            Control::Approach(0.4),
            Solver::PolonskyKeer,
            Start::Cold,
            &opts,
        )
        .unwrap();
    let got = cp
        .solve(
            Control::Approach(0.7),
            Solver::PolonskyKeer,
            Start::Previous,
            &opts,
        )
        .unwrap();
    let want = pk_direct(
        &h,
        ny,
        nx,
        Boundary::Free,
        Control::Approach(0.7),
        Some(&first.pressure),
    );
    assert!(same_bits(&got.pressure, &want.pressure));
    assert_eq!(got.iterations, want.iterations);
    let got = cp
        .solve(
            Control::Approach(0.7),
            Solver::PolonskyKeer,
            Start::Pressure(&first.pressure),
            &opts,
        )
        .unwrap();
    assert!(same_bits(&got.pressure, &want.pressure));
    // The exact solver from the support of a pressure field = from that contact set, and
    // from its own previous set = the direct solver keeping its factor.
    let set: Vec<usize> = (0..ny * nx).filter(|&i| first.pressure[i] > 0.0).collect();
    let mut cp = problem(&h, ny, nx, Boundary::Free);
    let got = cp
        .solve(
            Control::Approach(0.7),
            Solver::ActiveSet,
            Start::Pressure(&first.pressure),
            &opts,
        )
        .unwrap();
    let mut factor = Factor::new(ny * nx, LIMIT);
    let want = lh_direct(
        &h,
        ny,
        nx,
        Boundary::Free,
        0.7,
        true,
        &mut factor,
        lh::Start::Set(&set),
    );
    assert!(same_bits(&got.pressure, &want.pressure));
    assert_eq!(got.iterations, want.iterations);
    let got = cp
        .solve(
            Control::Approach(0.9),
            Solver::ActiveSet,
            Start::Previous,
            &opts,
        )
        .unwrap();
    let want = lh_direct(
        &h,
        ny,
        nx,
        Boundary::Free,
        0.9,
        true,
        &mut factor,
        lh::Start::Previous,
    );
    assert!(same_bits(&got.pressure, &want.pressure));
    assert_eq!(got.iterations, want.iterations);
    let got = cp
        .solve(
            Control::Approach(0.9),
            Solver::ActiveSet,
            Start::ContactSet(&set),
            &opts,
        )
        .unwrap();
    let mut factor = Factor::new(ny * nx, LIMIT);
    let want = lh_direct(
        &h,
        ny,
        nx,
        Boundary::Free,
        0.9,
        true,
        &mut factor,
        lh::Start::Set(&set),
    );
    assert!(same_bits(&got.pressure, &want.pressure));
}

#[test]
fn auto_policy_by_grid_size_and_control() {
    let a = Control::Approach(0.1);
    let m = Control::MeanPressure(0.1);
    assert_eq!(
        Solver::Auto.resolve(32 * 32, a, None).unwrap(),
        Solver::ActiveSet
    );
    assert_eq!(
        Solver::Auto.resolve(32 * 32 + 1, a, None).unwrap(),
        Solver::PolonskyKeer
    );
    assert_eq!(
        Solver::Auto.resolve(16, m, None).unwrap(),
        Solver::PolonskyKeer
    );
    assert!(Solver::ActiveSet.resolve(16, m, None).is_err());
    assert!(Solver::LawsonHanson.resolve(16, m, None).is_err());
    assert_eq!(
        Solver::LawsonHanson.resolve(1 << 20, a, None).unwrap(),
        Solver::LawsonHanson
    );
    // Auto on a small grid runs the active set: the same numbers as asking for it.
    let (ny, nx) = (12, 10);
    let h = surface(ny, nx);
    let opts = Options::default();
    let auto = problem(&h, ny, nx, Boundary::Free)
        .solve(a, Solver::Auto, Start::Cold, &opts)
        .unwrap();
    let exact = problem(&h, ny, nx, Boundary::Free)
        .solve(a, Solver::ActiveSet, Start::Cold, &opts)
        .unwrap();
    assert_eq!(auto.solver, Solver::ActiveSet);
    assert!(same_bits(&auto.pressure, &exact.pressure));
    for name in ["auto", "polonsky-keer", "active-set", "lawson-hanson"] {
        assert_eq!(Solver::from_name(name).unwrap().name(), name);
    }
    assert!(Solver::from_name("cg").is_err());
}
