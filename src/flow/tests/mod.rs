//! Tests of the Reynolds flow solvers, one file a concern; the shared problems and gap
//! generators are here.
use super::*;

mod dead_ends;
mod exact;
mod inputs;
mod ordering;
mod reference;
mod supernodal;
mod symbolic;
mod threshold;

/// [`crate::test_support::lcg`] from `seed` advanced once (the flow tests' inputs).
pub(super) fn lcg(seed: u64, n: usize) -> Vec<f64> {
    let (a, c) = crate::test_support::LCG;
    crate::test_support::lcg(seed.wrapping_mul(a).wrapping_add(c), n)
}

fn problem<'a>(gap: &'a [f64], ny: usize, nx: usize, axis: usize, periodic: bool) -> Problem<'a> {
    Problem {
        gap,
        contact: None,
        ny,
        nx,
        dx: 0.5,
        axis,
        viscosity: 2.0,
        pressure_drop: 3.0,
        periodic,
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

/// Random gaps with about `closed` of the cells in contact (gap 0).
fn random_gap(seed: u64, n: usize, closed: f64) -> Vec<f64> {
    let u = lcg(seed, 2 * n);
    (0..n)
        .map(|k| if u[n + k] < closed { 0.0 } else { 0.05 + u[k] })
        .collect()
}

/// A perfect maze (randomised depth-first carving) of one-cell-wide corridors on a
/// `(2h + 1) × (2w + 1)` grid, one opening on the inlet row and one on the outlet row, gaps
/// log-uniform over `decades` decades. Closed cells have gap 0.
fn maze_gap(seed: u64, h: usize, w: usize, decades: f64) -> (Vec<f64>, usize, usize) {
    let (ny, nx) = (2 * h + 1, 2 * w + 1);
    let mut open = vec![false; ny * nx];
    let u = lcg(seed, 4 * h * w + ny * nx);
    let mut draw = 0;
    let mut seen = vec![false; h * w];
    let mut stack = vec![(0usize, 0usize)];
    seen[0] = true;
    open[nx + 1] = true;
    while let Some(&(a, b)) = stack.last() {
        let mut nb = Vec::with_capacity(4);
        if a > 0 && !seen[(a - 1) * w + b] {
            nb.push((a - 1, b));
        }
        if a + 1 < h && !seen[(a + 1) * w + b] {
            nb.push((a + 1, b));
        }
        if b > 0 && !seen[a * w + b - 1] {
            nb.push((a, b - 1));
        }
        if b + 1 < w && !seen[a * w + b + 1] {
            nb.push((a, b + 1));
        }
        if nb.is_empty() {
            stack.pop();
            continue;
        }
        let pick = nb[((u[draw % u.len()] * nb.len() as f64) as usize).min(nb.len() - 1)];
        draw += 1;
        seen[pick.0 * w + pick.1] = true;
        open[(2 * pick.0 + 1) * nx + 2 * pick.1 + 1] = true;
        // The wall cell between the two maze cells.
        open[(a + pick.0 + 1) * nx + b + pick.1 + 1] = true;
        stack.push(pick);
    }
    open[1] = true; // inlet opening
    open[(ny - 1) * nx + nx - 2] = true; // outlet opening
    let v = lcg(seed ^ 0x5eed, ny * nx);
    let gap = (0..ny * nx)
        .map(|k| {
            if open[k] {
                10f64.powf(-decades * v[k] / 3.0)
            } else {
                0.0
            }
        })
        .collect();
    (gap, ny, nx)
}

/// The edge neighbours of cell `k` on a row-major `ny × nx` grid (no wrap along axis 0;
/// across axis 1 when `periodic`): above, below, left, right where they exist.
fn grid_neighbours(k: usize, ny: usize, nx: usize, periodic: bool) -> Vec<usize> {
    let (i, j) = (k / nx, k % nx);
    let mut nbs = Vec::with_capacity(4);
    if i > 0 {
        nbs.push(k - nx);
    }
    if i + 1 < ny {
        nbs.push(k + nx);
    }
    if j > 0 {
        nbs.push(k - 1);
    } else if periodic && nx > 1 {
        nbs.push(k + nx - 1);
    }
    if j + 1 < nx {
        nbs.push(k + 1);
    } else if periodic && nx > 1 {
        nbs.push(k + 1 - nx);
    }
    nbs
}

/// Open cells the way the solver defines them, 4-connectivity, no wrap: the cells of the one
/// inlet-to-outlet path of a perfect maze (a plain breadth-first search from the inlet
/// opening, then back along the parents from the outlet opening).
fn maze_path(gap: &[f64], ny: usize, nx: usize) -> Vec<usize> {
    let start = (0..nx).find(|&j| gap[j] > 0.0).unwrap();
    let goal = (ny - 1) * nx + (0..nx).find(|&j| gap[(ny - 1) * nx + j] > 0.0).unwrap();
    let mut parent = vec![usize::MAX; ny * nx];
    parent[start] = start;
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(k) = queue.pop_front() {
        for l in grid_neighbours(k, ny, nx, false) {
            if gap[l] > 0.0 && parent[l] == usize::MAX {
                parent[l] = k;
                queue.push_back(l);
            }
        }
    }
    let mut path = vec![goal];
    while *path.last().unwrap() != start {
        path.push(parent[*path.last().unwrap()]);
    }
    path.reverse();
    path
}

/// Random site field near the 4-connectivity site-percolation threshold (open fraction
/// `open`, ≈ 0.593 at threshold), gaps log-uniform over `decades` decades of `g³`.
fn threshold_gap(seed: u64, n: usize, open: f64, decades: f64) -> Vec<f64> {
    let u = lcg(seed, 2 * n);
    (0..n)
        .map(|k| {
            if u[n + k] < open {
                10f64.powf(-decades * u[k] / 3.0)
            } else {
                0.0
            }
        })
        .collect()
}

fn forced(solver: Solver) -> Options<'static> {
    Options {
        solver,
        ..Options::default()
    }
}

/// Flow along a one-cell-wide winding channel: the series resistance of the faces on the
/// one inlet-to-outlet path (found by breadth-first search), dead ends carrying nothing.
fn maze_oracle(gap: &[f64], ny: usize, nx: usize, pr: &Problem<'_>) -> f64 {
    let path = maze_path(gap, ny, nx);
    let c = |k: usize| gap[k].powi(3) / (12.0 * pr.viscosity);
    let mut r = 1.0 / (2.0 * c(path[0])) + 1.0 / (2.0 * c(*path.last().unwrap()));
    for w in path.windows(2) {
        r += 1.0 / assemble::harmonic(c(w[0]), c(w[1]));
    }
    pr.pressure_drop / r
}
