//! The dead ends of the spanning clusters: the classification against a brute-force
//! search, and the flow's pressures and fluxes there.
use super::*;
use crate::flow::dead_ends::{anchors, INLET, OUTLET};

/// The vertices of the inlet-to-outlet graph of `dead_ends` (cells, then `I = n`, `O = n + 1`)
/// reachable from `from` without passing `removed`, by breadth-first search.
fn reachable(
    spanning: &[bool],
    ny: usize,
    nx: usize,
    periodic: bool,
    from: usize,
    removed: usize,
) -> Vec<bool> {
    let n = ny * nx;
    let mut seen = vec![false; n + 2];
    let mut queue = std::collections::VecDeque::from([from]);
    seen[from] = true;
    while let Some(u) = queue.pop_front() {
        let mut next = Vec::new();
        if u == n || u == n + 1 {
            let row = if u == n { 0 } else { ny - 1 };
            next.push(if u == n { n + 1 } else { n });
            next.extend((0..nx).map(|j| row * nx + j).filter(|&k| spanning[k]));
        } else {
            let i = u / nx;
            if i == 0 {
                next.push(n);
            }
            if i + 1 == ny {
                next.push(n + 1);
            }
            next.extend(
                grid_neighbours(u, ny, nx, periodic)
                    .into_iter()
                    .filter(|&v| spanning[v]),
            );
        }
        for v in next {
            if v != removed && !seen[v] {
                seen[v] = true;
                queue.push_back(v);
            }
        }
    }
    seen
}

/// A spanning cell is a dead end exactly when some other vertex `v` (a cell or a
/// reservoir) cuts it off from both reservoirs (from the one that is not `v`); its anchor
/// is the cut vertex nearest the reservoirs: the one whose removal cuts off the most cells.
#[test]
fn dead_ends_are_the_cells_a_single_vertex_cuts_off_from_the_reservoirs() {
    for (seed, (ny, nx), periodic, open) in [
        (1, (9, 9), false, 0.62),
        (2, (12, 7), true, 0.6),
        (3, (7, 12), true, 0.7),
        (4, (10, 10), false, 0.75),
        (5, (6, 2), true, 0.8),
        (6, (1, 8), false, 0.9),
    ] {
        let n = ny * nx;
        let u = lcg(seed, n);
        let open: Vec<bool> = u.iter().map(|&v| v < open).collect();
        // The spanning cells: open cells joined to both reservoirs through open cells.
        let all_open = |k: usize| open[k];
        let from_in = reachable(&open, ny, nx, periodic, n, n + 1);
        let from_out = reachable(&open, ny, nx, periodic, n + 1, n);
        let spanning: Vec<bool> = (0..n)
            .map(|k| all_open(k) && from_in[k] && from_out[k])
            .collect();
        let got = anchors(&spanning, ny, nx, periodic);
        let mut expected = Vec::new();
        for k in (0..n).filter(|&k| spanning[k]) {
            let mut best: Option<(usize, usize)> = None;
            for v in (0..n + 2).filter(|&v| v != k && (v >= n || spanning[v])) {
                let seen = reachable(&spanning, ny, nx, periodic, k, v);
                let cut = (v == n || !seen[n]) && (v == n + 1 || !seen[n + 1]);
                if cut {
                    let size = seen.iter().filter(|&&s| s).count();
                    // The anchor cuts off the largest region holding `k`.
                    if best.is_none_or(|(_, s)| size > s) {
                        best = Some((v, size));
                    }
                }
            }
            if let Some((v, _)) = best {
                let a = match v {
                    v if v == n => INLET,
                    v if v == n + 1 => OUTLET,
                    v => v as u32,
                };
                expected.push((k as u32, a));
            }
        }
        assert_eq!(got, expected, "seed {seed}");
        if seed <= 3 {
            assert!(!expected.is_empty(), "seed {seed} has no dead end to check");
        }
    }
}

/// A walled pocket joined to the wide channel through one narrow cell is a dead end: its
/// fluid is at rest at the pressure of the channel cell it opens onto, however narrow the
/// neck (the factor of the whole system put it anywhere from 0.11 to ~0 of the drop for necks
/// of 1e-5 to 1e-17), with no flux through its faces, and the rate is that of the gap with
/// the pocket sealed.
#[test]
fn a_pocket_behind_one_neck_is_at_the_pressure_it_opens_onto() {
    let n = 61;
    let (a, b) = (20, 42);
    let m = (a + b) / 2;
    for neck in [1e-3, 1e-5, 1e-10, 1e-17] {
        let mut gap: Vec<f64> = lcg(31, n * n).iter().map(|&u| 0.5 + 0.5 * u).collect();
        let mut contact = vec![false; n * n];
        for t in a..=b {
            for k in [a * n + t, b * n + t, t * n + a, t * n + b] {
                contact[k] = true;
            }
        }
        let neck_cell = m * n + b;
        contact[neck_cell] = false;
        gap[neck_cell] = neck;
        let mut sealed_contact = contact.clone();
        sealed_contact[neck_cell] = true;
        for solver in [Solver::Cholesky, Solver::Multigrid] {
            let mut pr = problem(&gap, n, n, 0, true);
            pr.contact = Some(&contact);
            let sol = solve(&pr, &forced(solver)).unwrap();
            let mut sealed = problem(&gap, n, n, 0, true);
            sealed.contact = Some(&sealed_contact);
            let oracle = solve(&sealed, &forced(solver)).unwrap();
            assert!(rel(sol.flow_rate, oracle.flow_rate) < 1e-12);
            let outside = sol.pressure[neck_cell + 1];
            assert!(outside > 0.0 && outside < pr.pressure_drop);
            for i in a + 1..b {
                for j in a + 1..b {
                    assert_eq!(sol.pressure[i * n + j], outside, "{neck:e} {solver:?}");
                }
            }
            assert_eq!(sol.pressure[neck_cell], outside);
            // No flux across the neck's faces (axis 1: faces [m, b] and [m, b + 1]).
            assert_eq!(sol.flux_axis1[m * (n + 1) + b], 0.0);
            assert_eq!(sol.flux_axis1[m * (n + 1) + b + 1], 0.0);
            // The sealed pocket has no pressure (joined to no reservoir).
            assert!(oracle.pressure[m * n + m].is_nan());
            assert!(sol.n_unknowns < oracle.n_unknowns + 1);
        }
    }
}
