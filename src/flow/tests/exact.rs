//! Flows with exact answers: parallel plates, series conductances of one-dimensional gaps
//! and winding one-cell channels, symmetry under transposition, no spanning path, and the
//! conservation of every cell.
use super::*;

/// Uniform gap: the exact parallel-plate rate, `solver` forced.
fn parallel_plates_exact_with(solver: Solver) {
    for &(ny, nx, periodic) in &[
        (1, 1, false),
        (7, 5, false),
        (40, 33, true),
        (65, 300, false),
    ] {
        for axis in 0..2 {
            let g = 0.37;
            let gap = vec![g; ny * nx];
            let pr = problem(&gap, ny, nx, axis, periodic);
            let sol = solve(&pr, &forced(solver)).unwrap();
            let (w, l) = if axis == 0 {
                (nx as f64 * pr.dx, ny as f64 * pr.dx)
            } else {
                (ny as f64 * pr.dx, nx as f64 * pr.dx)
            };
            let exact = w * g.powi(3) * pr.pressure_drop / (12.0 * pr.viscosity * l);
            assert!(
                rel(sol.flow_rate, exact) < 1e-12,
                "{ny}x{nx}: {} vs {exact}",
                sol.flow_rate
            );
            assert!(rel(sol.inlet_flow_rate, exact) < 1e-12);
            assert!(rel(sol.conductance * pr.pressure_drop, exact) < 1e-12);
            assert_eq!(sol.n_unknowns, ny * nx);
        }
    }
}

#[test]
fn parallel_plates_exact() {
    parallel_plates_exact_with(Solver::Auto);
}

#[test]
fn parallel_plates_exact_multigrid() {
    parallel_plates_exact_with(Solver::Multigrid);
}

#[test]
fn one_dimensional_gap_series_conductances() {
    let (ny, nx) = (50, 6);
    let gi: Vec<f64> = (0..ny).map(|i| 0.1 + 0.02 * i as f64).collect();
    let gap: Vec<f64> = (0..ny * nx).map(|k| gi[k / nx]).collect();
    let pr = problem(&gap, ny, nx, 0, false);
    let sol = solve(&pr, &Options::default()).unwrap();
    let c: Vec<f64> = gi
        .iter()
        .map(|g| g.powi(3) / (12.0 * pr.viscosity))
        .collect();
    let mut r = 1.0 / (2.0 * c[0]) + 1.0 / (2.0 * c[ny - 1]);
    for i in 0..ny - 1 {
        r += (c[i] + c[i + 1]) / (2.0 * c[i] * c[i + 1]);
    }
    let exact = nx as f64 * pr.pressure_drop / r;
    assert!(
        rel(sol.flow_rate, exact) < 1e-12,
        "{} vs {exact}",
        sol.flow_rate
    );
    // No flux across the flow.
    assert!(sol.flux_axis1.iter().all(|&v| v.abs() < 1e-14 * exact));
}

/// A field and its transpose flowing along the other axis give the same bits, `solver`
/// forced.
fn transposed_field_along_axis1_is_the_same_flow_with(solver: Solver) {
    let (ny, nx) = (37, 52);
    let gap = random_gap(3, ny * nx, 0.3);
    let gt: Vec<f64> = (0..ny * nx).map(|k| gap[(k % ny) * nx + k / ny]).collect();
    for periodic in [false, true] {
        let a = solve(&problem(&gap, ny, nx, 0, periodic), &forced(solver)).unwrap();
        let b = solve(&problem(&gt, nx, ny, 1, periodic), &forced(solver)).unwrap();
        assert_eq!(a.flow_rate.to_bits(), b.flow_rate.to_bits());
        for i in 0..ny {
            for j in 0..nx {
                let (pa, pb) = (a.pressure[i * nx + j], b.pressure[j * ny + i]);
                assert!(pa.to_bits() == pb.to_bits(), "{pa} {pb}");
            }
        }
        for i in 0..=ny {
            for j in 0..nx {
                assert_eq!(a.flux_axis0[i * nx + j], b.flux_axis1[j * (ny + 1) + i]);
            }
        }
    }
}

#[test]
fn transposed_field_along_axis1_is_the_same_flow() {
    transposed_field_along_axis1_is_the_same_flow_with(Solver::Auto);
}

#[test]
fn transposed_field_along_axis1_is_the_same_flow_multigrid() {
    transposed_field_along_axis1_is_the_same_flow_with(Solver::Multigrid);
}

#[test]
fn nothing_spans_gives_exactly_zero() {
    let (ny, nx) = (20, 15);
    let mut gap = random_gap(5, ny * nx, 0.1);
    for j in 0..nx {
        gap[9 * nx + j] = 0.0;
    }
    let sol = solve(&problem(&gap, ny, nx, 0, true), &Options::default()).unwrap();
    assert_eq!(sol.flow_rate, 0.0);
    assert_eq!(sol.inlet_flow_rate, 0.0);
    assert_eq!(sol.n_unknowns, 0);
    assert!(sol
        .flux_axis0
        .iter()
        .chain(&sol.flux_axis1)
        .all(|&v| v == 0.0));
    // Inlet side at Δp, outlet side at 0, the blocking row NaN.
    for j in 0..nx {
        if gap[j] > 0.0 {
            assert_eq!(sol.pressure[j], 3.0);
        }
        if gap[(ny - 1) * nx + j] > 0.0 {
            assert_eq!(sol.pressure[(ny - 1) * nx + j], 0.0);
        }
        assert!(sol.pressure[9 * nx + j].is_nan());
    }
}

/// Every cell balanced and the two rates equal on a random gap, `solver` forced.
fn conservation_and_inlet_equals_outlet_with(solver: Solver) {
    let (ny, nx) = (64, 64);
    let gap = random_gap(9, ny * nx, 0.35);
    let sol = solve(&problem(&gap, ny, nx, 0, false), &forced(solver)).unwrap();
    assert!(sol.flow_rate > 0.0);
    assert!(rel(sol.inlet_flow_rate, sol.flow_rate) < 1e-9);
    assert!(sol.conservation < 1e-9, "{}", sol.conservation);
    assert!(sol.residual <= 1e-11);
}

#[test]
fn conservation_and_inlet_equals_outlet() {
    conservation_and_inlet_equals_outlet_with(Solver::Auto);
}

#[test]
fn conservation_and_inlet_equals_outlet_multigrid() {
    conservation_and_inlet_equals_outlet_with(Solver::Multigrid);
}

#[test]
fn winding_channel_matches_series_resistance() {
    // Conductances g³ over 2 decades: every solver must give the path's series resistance.
    let (gap, ny, nx) = maze_gap(3, 64, 64, 2.0);
    let pr = problem(&gap, ny, nx, 0, false);
    let q = maze_oracle(&gap, ny, nx, &pr);
    for solver in [Solver::Auto, Solver::Cholesky, Solver::Multigrid] {
        let sol = solve(&pr, &forced(solver)).unwrap();
        assert!(
            rel(sol.flow_rate, q) < 1e-10,
            "{solver:?}: {} vs {q}",
            sol.flow_rate
        );
        assert!(rel(sol.inlet_flow_rate, q) < 1e-9, "{solver:?}");
        assert!(sol.conservation < 1e-9, "{solver:?}: {}", sol.conservation);
    }
}

#[test]
fn cholesky_on_a_winding_channel_over_eight_decades() {
    // g³ over 8 decades along one winding one-cell channel (condition number near 1/ε):
    // the factor keeps ~1e-6 of the rate; refinement must not make it worse, and both ends
    // must still give the path's series resistance to that.
    let (gap, ny, nx) = maze_gap(3, 64, 64, 8.0);
    let pr = problem(&gap, ny, nx, 0, false);
    let q = maze_oracle(&gap, ny, nx, &pr);
    let sol = solve(&pr, &forced(Solver::Cholesky)).unwrap();
    assert_eq!(sol.solver, "cholesky");
    assert!(rel(sol.flow_rate, q) < 1e-5, "{} vs {q}", sol.flow_rate);
    assert!(
        rel(sol.inlet_flow_rate, q) < 1e-5,
        "{} vs {q}",
        sol.inlet_flow_rate
    );
}

/// A column of wide cells with two necks: the wide cells between them are joined to the rest
/// only through faces `g³ ~ 1e-15` of their own, which the rounded diagonal of the assembled
/// matrix loses. The rate is the exact series resistance (a sum of positive terms).
#[test]
fn wide_cells_between_two_necks_give_the_series_rate() {
    for &neck in &[1e-3, 1e-5, 1e-6] {
        let ny = 9;
        let mut gap = vec![1.0; ny];
        gap[3] = neck;
        gap[6] = neck;
        let pr = problem(&gap, ny, 1, 0, false);
        let sol = solve(&pr, &Options::default()).unwrap();
        let c: Vec<f64> = gap
            .iter()
            .map(|g| g * g * g / (12.0 * pr.viscosity))
            .collect();
        let mut r = 1.0 / (2.0 * c[0]) + 1.0 / (2.0 * c[ny - 1]);
        for k in 0..ny - 1 {
            r += (c[k] + c[k + 1]) / (2.0 * c[k] * c[k + 1]);
        }
        let q = pr.pressure_drop / r;
        assert!(
            rel(sol.flow_rate, q) < 1e-13,
            "{neck}: {} vs {q}",
            sol.flow_rate
        );
        assert!(rel(sol.inlet_flow_rate, q) < 1e-13);
        assert!(sol.conservation < 1e-6);
    }
}
