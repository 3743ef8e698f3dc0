//! The factor's fill-reducing order (every unknown exactly once, nested dissection) and its
//! analysis kept across calls.
use super::*;

/// `order_of` orders every unknown of the stencil of conductances `c` exactly once.
fn assert_orders_every_unknown(
    c: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
    order_of: fn(&assemble::Stencil, &[usize], usize) -> Vec<usize>,
) {
    let (st, _) = assemble::fine_stencil(c, ny, nx, periodic);
    let mut index = vec![usize::MAX; ny * nx];
    let mut m = 0;
    for (k, slot) in index.iter_mut().enumerate() {
        if st.active[k] {
            *slot = m;
            m += 1;
        }
    }
    let mut order = order_of(&st, &index, m);
    assert_eq!(order.len(), m, "{ny}x{nx} periodic={periodic}");
    order.sort_unstable();
    assert!(order.iter().enumerate().all(|(q, &u)| q == u));
}

#[test]
fn the_order_is_a_permutation_of_the_unknowns_with_and_without_blocks() {
    // 7 × 9 and 40 × 30 are ordered by 2 × 2 blocks, 150 × 150 cell by cell; about a third
    // of the cells closed.
    for &(ny, nx) in &[(7usize, 9usize), (40, 30), (150, 150), (1, 5)] {
        for periodic in [false, true] {
            let c: Vec<f64> = lcg((ny * 1000 + nx) as u64, ny * nx)
                .into_iter()
                .map(|u| if u < 0.35 { 0.0 } else { u })
                .collect();
            assert_orders_every_unknown(&c, ny, nx, periodic, |st, ix, m| {
                order::ordering(st, ix, m).0
            });
        }
    }
}

/// The nested dissection orders every unknown once, on thin and square grids, open and with
/// about a third of the cells closed, with and without wrap; and a mostly open grid above
/// its size threshold (ordered by it) gives the multigrid's flow rate.
#[test]
fn the_nested_dissection_is_a_permutation_and_gives_the_flow() {
    for &(ny, nx) in &[
        (1usize, 5usize),
        (2, 40),
        (3, 3),
        (40, 1),
        (77, 130),
        (200, 200),
    ] {
        for closed in [0.0, 0.35] {
            for periodic in [false, true] {
                let c: Vec<f64> = lcg((ny * 1000 + nx) as u64, ny * nx)
                    .into_iter()
                    .map(|u| if u < closed { 0.0 } else { u })
                    .collect();
                assert_orders_every_unknown(&c, ny, nx, periodic, |st, ix, m| {
                    order::nd_order(st, ix, m).0
                });
            }
        }
    }
    let (ny, nx) = (300, 300);
    let gap: Vec<f64> = lcg(5, ny * nx)
        .into_iter()
        .map(|u| if u < 0.1 { 0.0 } else { 0.2 + u })
        .collect();
    for periodic in [false, true] {
        let pr = problem(&gap, ny, nx, 0, periodic);
        let direct = solve(&pr, &Options::default()).unwrap();
        assert_eq!(direct.solver, "cholesky");
        let mg = solve(
            &pr,
            &Options {
                solver: Solver::Multigrid,
                ..Options::default()
            },
        )
        .unwrap();
        let rel = (direct.flow_rate - mg.flow_rate).abs() / mg.flow_rate;
        assert!(rel < 1e-9, "{} {} {rel:e}", direct.flow_rate, mg.flow_rate);
    }
}

/// A kept analysis: a gap closing in steps (`g − kδ`), each step solved on the analysis of
/// the first while its unknowns stay among them and above the reuse fraction; the rates as
/// a fresh analysis's to 1e-10, a different grid or a more open gap analysed afresh.
#[test]
fn kept_analysis_gives_the_fresh_rate() {
    let (ny, nx) = (70, 90);
    let base: Vec<f64> = lcg(21, ny * nx).into_iter().map(|u| 0.05 + u).collect();
    let kept = kept::KeptAnalysis::new(0);
    let opts = Options {
        analysis: Some(&kept),
        ..Options::default()
    };
    for k in 0..4 {
        let gap: Vec<f64> = base
            .iter()
            .map(|g| (g - 0.01 * k as f64).max(0.0))
            .collect();
        let pr = problem(&gap, ny, nx, 0, true);
        let a = solve(&pr, &opts).unwrap();
        let f = solve(&pr, &Options::default()).unwrap();
        assert_eq!(a.n_unknowns, f.n_unknowns);
        let rel = (a.flow_rate - f.flow_rate).abs() / f.flow_rate;
        assert!(rel <= 1e-10, "step {k}: {rel:e}");
    }
    assert_eq!(kept.made() + kept.reused(), 4);
    assert!(kept.reused() >= 1, "{} {}", kept.made(), kept.reused());
    // Another grid: a new analysis, no out-of-range access.
    let made = kept.made();
    let pr = problem(&base[..(ny - 1) * nx], ny - 1, nx, 0, true);
    solve(&pr, &opts).unwrap();
    assert_eq!(kept.made(), made + 1);
}
