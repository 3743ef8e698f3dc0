use super::columns::{Absolute, Columns, Offsets};
use super::cycle::{level_cycle, Fine, W_LEVELS};
use super::*;
use crate::flow::assemble::fine_stencil;
use crate::flow::tests::lcg as uniform;

/// A periodic `ny × nx` stencil with cell conductances spanning six decades.
fn rough(seed: u64, ny: usize, nx: usize) -> Stencil {
    let c: Vec<f64> = uniform(seed, ny * nx)
        .iter()
        .map(|u| 10f64.powf(-6.0 * u))
        .collect();
    fine_stencil(&c, ny, nx, true).0
}

#[test]
fn every_strong_f_pair_shares_a_c_neighbour() {
    // One block (10800 unknowns at most), and blocks of 97 and 1000 unknowns: the pairs
    // across block boundaries too. The second pass visiting only the F unknowns the first
    // left uncovered splits as visiting every F unknown.
    for (ny, nx) in [(60, 50), (120, 90)] {
        for seed in 0..4 {
            let st = rough(seed, ny, nx);
            let (cells, index) = unknowns(&st);
            let g = Fine {
                st: &st,
                cells: &cells,
                index: &index,
            };
            let wmax = strongest(&g);
            for block in [SPLIT_BLOCK, 97, 1000] {
                let (cidx, nc) = split_in_blocks(&g, &wmax, block);
                assert_eq!(
                    (cidx.clone(), nc),
                    split_with(&g, &wmax, block, false, NEAR_CAP),
                    "sifted and full second pass differ ({ny} × {nx}, seed {seed}, blocks of \
                     {block})"
                );
                assert!(nc > 0 && nc < g.n());
                for i in (0..g.n()).filter(|&i| cidx[i] == NONE) {
                    let ci: Vec<u32> = g
                        .row(i)
                        .filter(|&(j, w)| strong(w, wmax[i]) && cidx[j as usize] != NONE)
                        .map(|(j, _)| j)
                        .collect();
                    assert!(!ci.is_empty(), "F unknown {i} has no strong C neighbour");
                    for (k, w) in g.row(i) {
                        if cidx[k as usize] == NONE && strong(w, wmax[i]) {
                            assert!(
                                ci.iter().any(|&m| g.weight(k as usize, m) > 0.0),
                                "strong F pair {i}, {k} without a common C neighbour"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn fine_rows_from_the_stencil_are_its_faces() {
    // The rows read from the stencil against brute force over the grid's face arrays.
    for periodic in [false, true] {
        for (ny, nx) in [(7, 2), (9, 5)] {
            let c: Vec<f64> = uniform(3, ny * nx)
                .iter()
                .map(|&u| if u < 0.2 { 0.0 } else { u })
                .collect();
            let st = fine_stencil(&c, ny, nx, periodic).0;
            let (cells, index) = unknowns(&st);
            let g = Fine {
                st: &st,
                cells: &cells,
                index: &index,
            };
            for (i, &k) in cells.iter().enumerate() {
                let k = k as usize;
                let (r, col) = (k / nx, k % nx);
                let mut want: Vec<(u32, f64)> = Vec::new();
                let mut face = |l: usize, w: f64| {
                    if w > 0.0 && index[l] != NONE {
                        match want.iter_mut().find(|e| e.0 == index[l]) {
                            Some(e) => e.1 += w,
                            None => want.push((index[l], w)),
                        }
                    }
                };
                if col + 1 < nx {
                    face(k + 1, st.e[k]);
                } else if periodic {
                    face(r * nx, st.e[k]);
                }
                if col > 0 {
                    face(k - 1, st.e[k - 1]);
                } else if periodic {
                    face(r * nx + nx - 1, st.e[r * nx + nx - 1]);
                }
                if r + 1 < ny {
                    face(k + nx, st.s[k]);
                }
                if r > 0 {
                    face(k - nx, st.s[k - nx]);
                }
                want.sort_by_key(|e| e.0);
                let got: Vec<(u32, f64)> = g.row(i).collect();
                assert_eq!(got, want, "row {i} ({ny} × {nx}, periodic {periodic})");
                for &(j, w) in &want {
                    assert_eq!(g.weight(i, j), w);
                }
                assert_eq!(g.diag(i), st.d[k]);
                assert_eq!(g.reservoir(i), st.dir[k]);
            }
        }
    }
}

#[test]
fn cycle_is_symmetric_and_positive() {
    // A small hierarchy, and one deeper than the levels cycled twice ([`W_LEVELS`]).
    for (ny, nx, levels) in [(60, 50, 2), (200, 180, W_LEVELS + 3)] {
        let mg = Multigrid::new(rough(7, ny, nx));
        assert!(mg.n_levels() >= levels, "{} levels", mg.n_levels());
        let n = ny * nx;
        let u: Vec<f64> = uniform(1, n).iter().map(|v| v - 0.5).collect();
        let v: Vec<f64> = uniform(2, n).iter().map(|v| v - 0.5).collect();
        let (mut mu, mut mv) = (vec![0.0; n], vec![0.0; n]);
        mg.apply(&u, &mut mu);
        mg.apply(&v, &mut mv);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let (a, b) = (dot(&u, &mv), dot(&v, &mu));
        let scale = dot(&u, &u).sqrt() * dot(&mv, &mv).sqrt();
        assert!(
            (a - b).abs() <= 1e-12 * scale,
            "{ny} × {nx}: u·Mv = {a}, v·Mu = {b}"
        );
        assert!(dot(&u, &mu) > 0.0 && dot(&v, &mv) > 0.0);
    }
}

#[test]
fn a_warm_cycle_corrects_by_the_residual() {
    // From `x0`, a cycle gives `x0 + M (b − S x0)`, `M` the cycle from zero: what the
    // second coarse correction of the top levels relies on. On the level below `S` (whose
    // own coarse corrections are cycled twice) and on `S` itself.
    let mg = Multigrid::new(rough(31, 200, 180));
    assert!(
        mg.levels.len() > W_LEVELS + 2,
        "{} levels below the finest",
        mg.levels.len()
    );
    let mut bufs = mg.bufs.lock().unwrap();
    for depth in [1, 0] {
        let (g, n) = (&mg.levels[depth], mg.levels[depth].n);
        let b: Vec<f64> = uniform(32, n).iter().map(|u| u - 0.5).collect();
        let x0: Vec<f64> = uniform(33, n).iter().map(|u| u - 0.5).collect();
        let run = |bufs: &mut [Buffers], rhs: &[f64], x: &mut [f64], warm: bool| {
            let (levels, interps) = (&mg.levels[depth..], &mg.interps[depth..]);
            level_cycle(levels, interps, rhs, x, bufs, &mg.coarse, depth, warm);
        };
        // The level's own right-hand side and solution buffers are in use by the caller
        // only; below it, the cycle's.
        let mut warm = x0.clone();
        run(&mut bufs[depth..], &b, &mut warm, true);
        let mut r = vec![0.0; n];
        g.residual(&x0, &b, &mut r);
        let mut d = vec![0.0; n];
        run(&mut bufs[depth..], &r, &mut d, false);
        let want: Vec<f64> = x0.iter().zip(&d).map(|(x, d)| x + d).collect();
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = warm
            .iter()
            .zip(&want)
            .fold(0.0f64, |m, (a, w)| m.max((a - w).abs()));
        assert!(scale.is_finite() && scale > 0.0);
        assert!(
            worst <= 1e-12 * scale,
            "depth {depth}: {worst:e} off ({scale:e})"
        );
    }
}

#[test]
fn multigrid_memory_estimate_is_honest() {
    // Random fields with closed cells (a third) and six decades of conductance: the
    // hierarchy's bytes stay below the estimate, and the estimate within twice them.
    for (seed, ny, nx) in [(11, 300, 200), (12, 256, 256)] {
        let st = holed(seed, ny, nx, true, 0.33);
        let m = st.active.iter().filter(|&&a| a).count();
        let mg = Multigrid::new(st);
        let (bytes, est) = (mg.bytes(), memory_estimate(m));
        println!(
            "{ny} × {nx}: {m} unknowns, {:.0} bytes per unknown, complexity {:.2}",
            bytes as f64 / m as f64,
            mg.complexity()
        );
        assert!(mg.n_levels() >= 4);
        assert!(
            bytes <= est && 2 * bytes >= est,
            "{bytes} bytes ({:.0} per unknown, complexity {:.2}) against the estimate {est}",
            bytes as f64 / m as f64,
            mg.complexity()
        );
    }
}

/// The first pass from its records (each holding up to `cap` neighbours) against the rows
/// read from the operator alone (capacity 0), on one block and on blocks of 97 unknowns.
fn assert_records_split_as_rows(g: &impl Rows, what: &str) {
    let wmax = strongest(g);
    for block in [SPLIT_BLOCK, 97] {
        let rows = split_with(g, &wmax, block, true, 0);
        assert!(rows.1 > 0, "{what}: some C unknowns");
        for cap in [1, 3, NEAR_CAP] {
            assert_eq!(
                split_with(g, &wmax, block, true, cap),
                rows,
                "{what}: records of {cap} neighbours split otherwise (blocks of {block})"
            );
        }
    }
}

#[test]
fn the_first_pass_splits_the_same_from_records_as_from_rows() {
    // The finest level (four faces a row) and the compressed levels below it (longer rows:
    // with small capacities most rows are read from the operator, some from records).
    for seed in 0..3 {
        let st = holed(seed, 90, 80, true, 0.3);
        let (cells, index) = unknowns(&st);
        let fine = Fine {
            st: &st,
            cells: &cells,
            index: &index,
        };
        assert_records_split_as_rows(&fine, &format!("finest level, seed {seed}"));
        let mg = Multigrid::new(st.clone());
        assert!(mg.levels.len() >= 3, "a hierarchy of several levels");
        for (l, g) in mg.levels[..mg.levels.len() - 1].iter().enumerate() {
            assert_records_split_as_rows(g, &format!("level {l}, seed {seed}"));
        }
    }
}

#[test]
fn split_in_blocks_is_the_same_on_one_and_two_threads() {
    let st = rough(5, 80, 70);
    let (cells, index) = unknowns(&st);
    let g = Fine {
        st: &st,
        cells: &cells,
        index: &index,
    };
    let wmax = strongest(&g);
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool")
            .install(|| split_in_blocks(&g, &wmax, 211))
    };
    assert_eq!(run(1), run(2));
}

/// A stencil with a share `closed` of the cells closed and six decades of conductance.
fn holed(seed: u64, ny: usize, nx: usize, periodic: bool, closed: f64) -> Stencil {
    let u = uniform(seed, ny * nx);
    let c: Vec<f64> = uniform(seed + 100, ny * nx)
        .iter()
        .zip(&u)
        .map(|(&v, &o)| {
            if o < closed {
                0.0
            } else {
                10f64.powf(-6.0 * v)
            }
        })
        .collect();
    fine_stencil(&c, ny, nx, periodic).0
}

/// The dense matrix of a level's rows.
fn dense(g: &impl Rows) -> Vec<Vec<f64>> {
    let n = g.n();
    let mut a = vec![vec![0.0; n]; n];
    for (i, row) in a.iter_mut().enumerate() {
        row[i] = g.diag(i);
        for (j, w) in g.row(i) {
            row[j as usize] -= w;
        }
    }
    a
}

#[test]
fn red_unknowns_are_independent_and_their_schur_complement_is_exact() {
    // Odd and even widths, wrapped and walled, the 2-wide wrapped row: no face joins two red
    // unknowns, and the stored S equals A_BB − A_BR D_R⁻¹ A_RB computed densely, to the
    // single precision of its faces.
    for (seed, ny, nx, periodic) in [
        (1, 9, 7, true),
        (2, 9, 7, false),
        (3, 8, 6, true),
        (4, 7, 2, true),
        (5, 11, 9, true),
    ] {
        let st = holed(seed, ny, nx, periodic, 0.2);
        let (cells, index) = unknowns(&st);
        let top = Fine {
            st: &st,
            cells: &cells,
            index: &index,
        };
        let mut red = Reduction::new(&top);
        let n = top.n();
        let s = red.schur(&top);
        let is_red = |i: usize| red.is_red(i);
        for i in (0..n).filter(|&i| is_red(i)) {
            for (j, _) in top.row(i) {
                assert!(
                    !is_red(j as usize),
                    "red {i} and {j} share a face ({ny} × {nx})"
                );
            }
        }
        let a = dense(&top);
        let got = dense(&s);
        let kept = &red.kept;
        for (p, &i) in kept.iter().enumerate() {
            for (q, &j) in kept.iter().enumerate() {
                let (i, j) = (i as usize, j as usize);
                let mut want = a[i][j];
                for r in (0..n).filter(|&r| is_red(r)) {
                    want -= a[i][r] * a[r][j] / a[r][r];
                }
                let scale = a[i][i].abs().max(a[j][j].abs());
                assert!(
                    (got[p][q] - want).abs() <= 1e-6 * scale,
                    "S[{p}][{q}] = {} against {want} ({ny} × {nx}, periodic {periodic})",
                    got[p][q]
                );
            }
        }
    }
}

#[test]
fn the_reduction_with_an_exact_coarse_solve_is_the_inverse() {
    // 24 × 40 with closed cells: more unknowns than the dense factor takes, but S (half of
    // them) is the coarsest level, so the preconditioner is A⁻¹ but for the single precision
    // of S's faces.
    let st = holed(9, 24, 40, true, 0.2);
    let n = st.active.iter().filter(|&&a| a).count();
    assert!(n > COARSEST);
    let mg = Multigrid::new(st);
    assert_eq!(mg.n_levels(), 2, "sizes {:?}", mg.sizes());
    let x: Vec<f64> = uniform(4, n).iter().map(|v| v - 0.5).collect();
    let mut ax = vec![0.0; n];
    mg.operator(&x, &mut ax);
    let mut z = vec![0.0; n];
    mg.precondition(&ax, &mut z);
    let err = x
        .iter()
        .zip(&z)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(err <= 1e-4, "largest error {err} of M⁻¹ A x against x");
}

#[test]
fn the_schur_product_is_s_times_v() {
    // `S v` from the stencil against the dense `A_BB − A_BR D_R⁻¹ A_RB` in double
    // precision on small grids, and on grids of several product blocks against the fine
    // operator: with `x_B = v` and `x_R = D_R⁻¹ W_RB v` (the extension of `v` with `r = 0`),
    // `A x` is `S v` on the kept unknowns and 0 on the red ones.
    for (seed, ny, nx, periodic) in [(1, 9, 7, true), (2, 9, 7, false), (4, 7, 2, true)] {
        let st = holed(seed, ny, nx, periodic, 0.2);
        let (cells, index) = unknowns(&st);
        let top = Fine {
            st: &st,
            cells: &cells,
            index: &index,
        };
        let red = Reduction::new(&top);
        let n = top.n();
        let a = dense(&top);
        let kept = &red.kept;
        let v: Vec<f64> = uniform(seed + 10, kept.len())
            .iter()
            .map(|u| u - 0.3)
            .collect();
        let mut y = vec![0.0; kept.len()];
        red.schur_product(&top, &v, &mut y);
        for (p, &i) in kept.iter().enumerate() {
            let i = i as usize;
            let mut want = 0.0;
            for (q, &j) in kept.iter().enumerate() {
                let j = j as usize;
                let mut s = a[i][j];
                for r in (0..n).filter(|&r| red.is_red(r)) {
                    s -= a[i][r] * a[r][j] / a[r][r];
                }
                want += s * v[q];
            }
            assert!(
                (y[p] - want).abs() <= 1e-12 * a[i][i],
                "(S v)[{p}] = {} against {want} ({ny} × {nx}, periodic {periodic})",
                y[p]
            );
        }
    }
    for (seed, ny, nx, periodic) in [(6, 300, 301, true), (7, 300, 300, false)] {
        let st = holed(seed, ny, nx, periodic, 0.2);
        let (cells, index) = unknowns(&st);
        let top = Fine {
            st: &st,
            cells: &cells,
            index: &index,
        };
        let red = Reduction::new(&top);
        let n = top.n();
        assert!(red.len() > PRODUCT_BLOCK, "{} kept unknowns", red.len());
        let v: Vec<f64> = uniform(seed, red.len()).iter().map(|u| u - 0.3).collect();
        let mut y = vec![0.0; red.len()];
        red.schur_product(&top, &v, &mut y);
        let mut x = vec![0.0; n];
        red.extend(&top, &vec![0.0; n], &v, &mut x);
        let mut ax = vec![0.0; n];
        top.product(&x, &mut ax);
        for i in 0..n {
            let k = cells[i] as usize;
            let scale = st.d[k];
            let want = if red.is_red(i) {
                0.0
            } else {
                y[red.slot[i] as usize]
            };
            assert!(
                (ax[i] - want).abs() <= 1e-12 * scale,
                "(A x)[{i}] = {} against {want} ({ny} × {nx}, periodic {periodic})",
                ax[i]
            );
        }
    }
}

#[test]
fn the_inner_product_is_the_stored_s_within_its_rounding() {
    // Conductances over six decades: every face of S a normal single, so the inner solves'
    // product is the stored S, within single precision's rounding of each face of the exact
    // product (and not bit for bit the same: it is the stored one).
    for (seed, ny, nx, periodic) in [(11, 60, 61, true), (12, 64, 50, false)] {
        let st = holed(seed, ny, nx, periodic, 0.2);
        let mg = Multigrid::new(st);
        let red = mg.reduction.as_ref().expect("a reduction");
        assert!(red.faithful(), "six decades are stored faithfully");
        let s = &mg.levels[0];
        let v: Vec<f64> = uniform(seed, s.n).iter().map(|u| u - 0.3).collect();
        let (mut exact, mut inner) = (vec![0.0; s.n], vec![0.0; s.n]);
        mg.reduced_product(&v, &mut exact);
        mg.inner_reduced_product(&v, &mut inner);
        assert_ne!(exact, inner, "the stored faces, not the stencil's");
        for i in 0..s.n {
            // Each face within 2^-24 of the exact one, the diagonal a sum of them.
            let scale: f64 =
                s.d[i] * v[i].abs() + s.row(i).map(|(j, w)| w * v[j as usize].abs()).sum::<f64>();
            assert!(
                (inner[i] - exact[i]).abs() <= 2f64.powi(-22) * scale,
                "(S v)[{i}]: stored {} against exact {} ({ny} × {nx})",
                inner[i],
                exact[i]
            );
        }
    }
}

#[test]
fn a_face_below_single_precision_makes_the_inner_product_exact() {
    // One cell 1e-50 times narrower in conductance than the rest: its faces in S round
    // to 0 in single precision, so the inner solves apply S from the stencil.
    let (ny, nx) = (40, 36);
    let mut c: Vec<f64> = uniform(21, ny * nx).iter().map(|u| 0.5 + u).collect();
    c[20 * nx + 17] = 1e-50;
    let st = fine_stencil(&c, ny, nx, true).0;
    let mg = Multigrid::new(st);
    assert!(!mg.reduction.as_ref().expect("a reduction").faithful());
    let n = mg.levels[0].n;
    let v: Vec<f64> = uniform(22, n).iter().map(|u| u - 0.3).collect();
    let (mut exact, mut inner) = (vec![0.0; n], vec![0.0; n]);
    mg.reduced_product(&v, &mut exact);
    mg.inner_reduced_product(&v, &mut inner);
    assert_eq!(exact, inner);
}

/// The ℓ1 hybrid Gauss–Seidel sweep by its definition (module docs), in plain arithmetic:
/// rows in blocks of [`CHUNK`], Gauss–Seidel inside a block, other blocks' values from
/// before the sweep, each divisor enlarged by the row's faces outside its block.
fn sweep_by_definition(g: &Graph, b: &[f64], x: &mut [f64], reverse: bool) {
    let old = x.to_vec();
    for i0 in (0..g.n).step_by(CHUNK) {
        let block = i0..(i0 + CHUNK).min(g.n);
        let rows: Vec<usize> = if reverse {
            block.clone().rev().collect()
        } else {
            block.clone().collect()
        };
        for i in rows {
            let (mut v, mut div) = (b[i] - g.d[i] * x[i], g.d[i]);
            for p in g.ptr[i]..g.ptr[i + 1] {
                let (j, w) = (g.column(p, i), f64::from(g.w[p]));
                if block.contains(&j) {
                    v += w * x[j];
                } else {
                    div += w.abs();
                    v += w * old[j];
                }
            }
            x[i] += v / div;
        }
    }
}

/// The largest `|want_i|` and the largest `|x_i − want_i|`.
fn largest_and_worst(want: &[f64], x: &[f64]) -> (f64, f64) {
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = x
        .iter()
        .zip(want)
        .fold(0.0f64, |m, (a, w)| m.max((a - w).abs()));
    (scale, worst)
}

#[test]
fn the_sweep_is_l1_gauss_seidel_in_blocks() {
    // `S` and the level below it of a 300² field with every cell open (so every unknown
    // reaches a reservoir: no singular rows), each of several blocks; forward, reverse,
    // forward again from a random start, against the definition to round-off.
    let mg = Multigrid::new(rough(21, 300, 300));
    for g in &mg.levels[..2] {
        assert!(g.n > CHUNK, "{} unknowns: two blocks or more", g.n);
        let b: Vec<f64> = uniform(22, g.n).iter().map(|u| u - 0.5).collect();
        let start: Vec<f64> = uniform(23, g.n).iter().map(|u| u - 0.5).collect();
        let (mut x, mut want) = (start.clone(), start);
        let mut scratch = vec![0.0; g.n];
        for reverse in [false, true, false] {
            g.smooth(&b, &mut x, &mut scratch, reverse);
            sweep_by_definition(g, &b, &mut want, reverse);
            let (scale, worst) = largest_and_worst(&want, &x);
            assert!(scale.is_finite() && x.iter().all(|v| v.is_finite()));
            assert!(
                worst <= 1e-13 * scale,
                "{} unknowns, reverse {reverse}: {worst:e} off (largest value {scale:e})",
                g.n
            );
        }
    }
}

#[test]
fn the_sweep_from_zero_and_its_residual_follow_the_definitions() {
    // The cycle's first sweep from x = 0 reads only the faces before each row in its block,
    // and the residual after it only the others: against the sweep by its definition from
    // 0 and `b − A x` summed from every face, on `S` and the level below it (several
    // blocks each) of a 300² field, for right-hand sides of either sign.
    let mg = Multigrid::new(rough(31, 300, 300));
    for g in &mg.levels[..2] {
        assert!(g.n > CHUNK, "{} unknowns: two blocks or more", g.n);
        let b: Vec<f64> = uniform(32, g.n).iter().map(|u| u - 0.5).collect();
        let mut x = vec![f64::NAN; g.n];
        g.smooth_from_zero(&b, &mut x);
        let mut want = vec![0.0; g.n];
        sweep_by_definition(g, &b, &mut want, false);
        let (scale, worst) = largest_and_worst(&want, &x);
        assert!(scale > 0.0 && scale.is_finite());
        assert!(
            worst <= 1e-13 * scale,
            "{} unknowns: sweep {worst:e} off",
            g.n
        );
        let mut r = vec![f64::NAN; g.n];
        g.residual_after_zero_sweep(&x, &mut r);
        for i in 0..g.n {
            let mut v = b[i] - g.d[i] * x[i];
            let mut size = b[i].abs() + (g.d[i] * x[i]).abs();
            for p in g.ptr[i]..g.ptr[i + 1] {
                let t = f64::from(g.w[p]) * x[g.column(p, i)];
                v += t;
                size += t.abs();
            }
            assert!(
                (r[i] - v).abs() <= 1e-13 * size,
                "row {i} of {}: residual {} against {v} (terms up to {size:e})",
                g.n,
                r[i]
            );
        }
    }
}

/// The sweep from 0 with its residual, and a reversed sweep from `start` with the plain
/// residual after it, reading the columns through `cols`.
fn four_loops(g: &Graph, cols: &impl Columns, b: &[f64], start: &[f64]) -> [Vec<f64>; 4] {
    let (mut x0, mut r0) = (vec![0.0; g.n], vec![0.0; g.n]);
    g.smooth_from_zero_with(cols, b, &mut x0);
    g.residual_after_zero_sweep_with(cols, &x0, &mut r0);
    let (mut x1, mut r1) = (start.to_vec(), vec![0.0; g.n]);
    g.smooth_with(cols, b, &mut x1, start, true);
    g.residual_with(cols, &x1, b, &mut r1);
    [x0, r0, x1, r1]
}

#[test]
fn columns_as_offsets_give_the_same_bits_as_absolute_columns() {
    // The built levels keep their columns as 16-bit offsets from the row; the cycle's four
    // loops read through either storage: the same results to the bit, on `S` and the level
    // below it of a 300² field (several blocks each), against the absolute columns decoded
    // from the offsets and checked against the rows' own definition of a face.
    let mg = Multigrid::new(rough(41, 300, 300));
    for g in &mg.levels[..2] {
        assert!(
            g.col.is_empty() && g.near.len() == g.entries(),
            "columns compressed"
        );
        let abs: Vec<u32> = (0..g.n)
            .flat_map(|i| (g.ptr[i]..g.ptr[i + 1]).map(move |p| (p, i)))
            .map(|(p, i)| g.column(p, i) as u32)
            .collect();
        assert!(abs.iter().all(|&j| (j as usize) < g.n));
        assert!((0..g.n).all(|i| abs[g.ptr[i]..g.ptr[i + 1]].windows(2).all(|w| w[0] < w[1])));
        let (a, o) = (Absolute(&abs), Offsets(&g.near));
        let b: Vec<f64> = uniform(42, g.n).iter().map(|u| u - 0.5).collect();
        let start: Vec<f64> = uniform(43, g.n).iter().map(|u| u - 0.5).collect();
        let with_abs = four_loops(g, &a, &b, &start);
        let with_offsets = four_loops(g, &o, &b, &start);
        assert!(with_abs == with_offsets, "{} unknowns: results differ", g.n);
        assert!(with_abs[1].iter().any(|&v| v != 0.0) && with_abs[3].iter().any(|&v| v != 0.0));
    }
}

#[test]
fn offsets_that_do_not_fit_16_bits_keep_absolute_columns() {
    // Row 0: columns 1 and 5; row 1: column 0; row 2: column 2 + 32767 (fits), then the
    // same with column 2 + 32768 (does not); and a row whose only column is the one before.
    let ptr = [0, 2, 3, 4];
    assert_eq!(
        super::columns::offsets(&ptr, &[1, 5, 0, 32769]),
        Some(vec![1, 5, -1, 32767])
    );
    assert_eq!(super::columns::offsets(&ptr, &[1, 5, 0, 32770]), None);
    assert_eq!(super::columns::offsets(&[0, 0, 1], &[0]), Some(vec![-1]));
}
