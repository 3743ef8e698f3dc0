//! The numeric supernodal factor against faer's on the same analysis, and the residual of
//! its solves.
use super::*;
use crate::flow::llt::llt_values;
use crate::flow::substitution::{supernodal_solve, Supernode};
use crate::flow::symbolic::Layout;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Par, Side};

/// The lower triangle of a wrapped `ny × nx` grid's operator: face conductances `10^(-6u)`
/// (`u` uniform), the diagonal their sum plus `shift` times the largest (negative `shift`
/// at cell `bad`: not positive definite there).
pub(super) fn grid_operator(
    ny: usize,
    nx: usize,
    seed: u64,
    bad: Option<usize>,
) -> SparseColMat<usize, f64> {
    let n = ny * nx;
    let u = lcg(seed, 2 * n);
    let c: Vec<f64> = u.iter().map(|&v| 10f64.powf(-6.0 * v)).collect();
    let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut diag = vec![1e-3; n];
    for k in 0..n {
        let (i, j) = (k / nx, k % nx);
        for (l, g) in [
            (i * nx + (j + 1) % nx, c[2 * k]),
            (((i + 1) % ny) * nx + j, c[2 * k + 1]),
        ] {
            let (lo, hi) = (k.min(l), k.max(l));
            cols[lo].push((hi, -g));
            diag[k] += g;
            diag[l] += g;
        }
    }
    if let Some(b) = bad {
        diag[b] = -1.0;
    }
    let (mut ptr, mut rows, mut vals) = (vec![0], Vec::new(), Vec::new());
    for (k, col) in cols.iter_mut().enumerate() {
        col.push((k, diag[k]));
        col.sort_by_key(|e| e.0);
        for &(r, v) in col.iter() {
            rows.push(r);
            vals.push(v);
        }
        ptr.push(rows.len());
    }
    SparseColMat::new(
        SymbolicSparseColMat::new_checked(n, n, ptr, None, rows),
        vals,
    )
}

pub(super) fn analysis(a: &SparseColMat<usize, f64>, amd: bool) -> SymbolicCholesky<usize> {
    let params = CholeskySymbolicParams {
        supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
        ..Default::default()
    };
    let id: Vec<usize> = (0..a.nrows()).collect();
    let order = if amd {
        SymmetricOrdering::Amd
    } else {
        SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(&id, &id, id.len()))
    };
    factorize_symbolic_cholesky(a.symbolic(), Side::Lower, order, params).unwrap()
}

/// The supernodal structure of a supernodal analysis.
fn supernodes(symbolic: &SymbolicCholesky<usize>) -> Layout<'_> {
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sn) => Layout::of_faer(sn),
        SymbolicCholeskyRaw::Simplicial(_) => panic!("a supernodal analysis"),
    }
}

/// `a`'s analysis ([`analysis`]) and the values of its factor ([`factor_values`]).
fn factored(a: &SparseColMat<usize, f64>, amd: bool) -> (SymbolicCholesky<usize>, Vec<f64>) {
    use crate::flow::llt::permuted_lower;
    use crate::flow::supernodal::factor_values;
    let symbolic = analysis(a, amd);
    let lower = match symbolic.perm() {
        Some(p) => permuted_lower(a, p.arrays().1),
        None => a.clone(),
    };
    let sn = supernodes(&symbolic);
    let mut values = vec![0.0; sn.len_val()];
    factor_values(sn, lower.as_ref(), &mut values, sn.nrows()).unwrap();
    (symbolic, values)
}

/// `‖b − A x‖₂ / ‖b‖₂` with `A` given by its lower triangle `a`.
fn relative_residual(a: &SparseColMat<usize, f64>, x: &[f64], b: &[f64]) -> f64 {
    let mut r = b.to_vec();
    let (ptr, rows, vals) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    for j in 0..a.ncols() {
        for p in ptr[j]..ptr[j + 1] {
            let i = rows[p];
            r[i] -= vals[p] * x[j];
            if i != j {
                r[j] -= vals[p] * x[i];
            }
        }
    }
    let norm = |v: &[f64]| v.iter().map(|t| t * t).sum::<f64>().sqrt();
    norm(&r) / norm(b)
}

/// The factor's values match faer's numeric factor on the same analysis, with a fill-reducing
/// order (the operator permuted; on 64 × 64, supernodes past the dense threshold) and in
/// grid order, and its solve leaves a residual at round-off.
#[test]
fn the_supernodal_factor_matches_faers_and_solves() {
    for (ny, nx, amd) in [
        (24, 31, true),
        (40, 40, false),
        (9, 70, true),
        (64, 64, true),
    ] {
        let a = grid_operator(ny, nx, 7 + ny as u64, None);
        let symbolic = analysis(&a, amd);
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            panic!("a supernodal analysis")
        };
        let sn = Layout::of_faer(sn);
        if ny == 64 {
            // Wide supernodes with rows below them: the dense factor and product.
            let wide = (0..sn.n_supernodes())
                .filter(|&s| {
                    let rp = sn.col_ptr_for_row_idx();
                    sn.supernode_end()[s] - sn.supernode_begin()[s] >= 32 && rp[s + 1] > rp[s]
                })
                .count();
            assert!(wide > 0, "no wide supernode with a pattern");
        }
        let ours = llt_values(&symbolic, &a, Par::Seq).unwrap();
        let mut theirs = vec![0.0; symbolic.len_val()];
        let scratch = symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default());
        let mut buf = MemBuffer::new(scratch);
        symbolic
            .factorize_numeric_llt::<f64>(
                &mut theirs,
                a.as_ref(),
                Side::Lower,
                Default::default(),
                Par::Seq,
                MemStack::new(&mut buf),
                Default::default(),
            )
            .unwrap();
        // Entries of the diagonal blocks' upper triangles are not part of the factor.
        for s in 0..sn.n_supernodes() {
            let node = Supernode::of(sn, &ours, s);
            let them = Supernode::of(sn, &theirs, s);
            for c in 0..node.ncols {
                let (x, y) = (node.column(c), them.column(c));
                for r in c..x.len() {
                    let scale = y[c].abs().max(1e-300);
                    assert!(
                        (x[r] - y[r]).abs() <= 1e-11 * scale,
                        "{ny}×{nx}: supernode {s} column {c} row {r}: {} against {}",
                        x[r],
                        y[r]
                    );
                }
            }
        }
        // `A x = b` through the factor's order, residual against the operator.
        let n = ny * nx;
        let b = lcg(3, n);
        let (fwd, inv) = match symbolic.perm() {
            Some(p) => (p.arrays().0.to_vec(), p.arrays().1.to_vec()),
            None => ((0..n).collect(), (0..n).collect()),
        };
        let mut w: Vec<f64> = fwd.iter().map(|&q| b[q]).collect();
        supernodal_solve(sn, &ours, &mut w);
        let x: Vec<f64> = (0..n).map(|q| w[inv[q]]).collect();
        let rel = relative_residual(&a, &x, &b);
        assert!(rel < 1e-12, "{ny}×{nx}: relative residual {rel:e}");
    }
}

/// A matrix that is not positive definite is refused, not factored into NaNs.
#[test]
fn the_supernodal_factor_refuses_a_matrix_that_is_not_positive_definite() {
    for amd in [true, false] {
        let a = grid_operator(20, 20, 5, Some(137));
        let symbolic = analysis(&a, amd);
        let err = llt_values(&symbolic, &a, Par::Seq).expect_err("a refusal");
        assert!(format!("{err}").contains("not positive"), "{err}");
    }
}

/// The factor and the substitutions give the same bits whichever build of their loops runs
/// (the baseline instruction set, or AVX2 on a CPU that has it): with a fill-reducing order,
/// past the dense threshold, and in grid order.
#[test]
fn the_wide_and_plain_builds_give_the_same_bits() {
    use crate::flow::llt::permuted_lower;
    use crate::flow::substitution::{
        supernodal_backward, supernodal_backward_plain, supernodal_forward,
        supernodal_forward_plain,
    };
    use crate::flow::supernodal::{factor_values, factor_values_plain};
    for (ny, nx, amd) in [(24, 31, true), (40, 40, false), (64, 64, true)] {
        let a = grid_operator(ny, nx, 11 + ny as u64, None);
        let symbolic = analysis(&a, amd);
        let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
            panic!("a supernodal analysis")
        };
        let sn = Layout::of_faer(sn);
        let a = match symbolic.perm() {
            Some(p) => permuted_lower(&a, p.arrays().1),
            None => a,
        };
        // Whatever the values held on entry (zeros, or NaN): the same factor.
        let (mut wide, mut plain) = (vec![0.0; sn.len_val()], vec![f64::NAN; sn.len_val()]);
        factor_values(sn, a.as_ref(), &mut wide, sn.nrows()).unwrap();
        factor_values_plain(sn, a.as_ref(), &mut plain, sn.nrows()).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&wide), bits(&plain), "{ny}×{nx}: factor");
        let mut stale = vec![f64::NAN; sn.len_val()];
        factor_values(sn, a.as_ref(), &mut stale, sn.nrows()).unwrap();
        assert_eq!(bits(&stale), bits(&wide), "{ny}×{nx}: factor over NaN");
        let n = ny * nx;
        let b = lcg(9, 2 * n);
        let (mut w1, mut p1) = (b[..n].to_vec(), b[..n].to_vec());
        supernodal_forward::<1>(sn, &wide, &mut w1, n);
        supernodal_forward_plain::<1>(sn, &wide, &mut p1, n);
        supernodal_backward::<1>(sn, &wide, &mut w1, n);
        supernodal_backward_plain::<1>(sn, &wide, &mut p1, n);
        assert_eq!(bits(&w1), bits(&p1), "{ny}×{nx}: one column");
        let (mut w2, mut p2) = (b.clone(), b.clone());
        supernodal_forward::<2>(sn, &wide, &mut w2, n);
        supernodal_forward_plain::<2>(sn, &wide, &mut p2, n);
        supernodal_backward::<2>(sn, &wide, &mut w2, n);
        supernodal_backward_plain::<2>(sn, &wide, &mut p2, n);
        assert_eq!(bits(&w2), bits(&p2), "{ny}×{nx}: two columns");
    }
}

/// Two right-hand sides solved interleaved (`K = 2`, one pass over the factor) give the
/// bits of each solved alone (`K = 1`): the flow's answer does not depend on whether its
/// columns were solved together (a factor in halves) or apart (one factor, two threads).
#[test]
fn interleaved_columns_give_the_bits_of_each_alone() {
    use crate::flow::substitution::{supernodal_backward, supernodal_forward};
    for (ny, nx, amd) in [(24, 31, true), (40, 40, false), (64, 64, true)] {
        let (symbolic, values) = factored(&grid_operator(ny, nx, 5 + nx as u64, None), amd);
        let sn = supernodes(&symbolic);
        let n = ny * nx;
        let b = lcg(17, 2 * n);
        let alone: Vec<Vec<u64>> = (0..2)
            .map(|c| {
                let mut w = b[c * n..(c + 1) * n].to_vec();
                supernodal_forward::<1>(sn, &values, &mut w, n);
                supernodal_backward::<1>(sn, &values, &mut w, n);
                w.iter().map(|v| v.to_bits()).collect()
            })
            .collect();
        let mut w2: Vec<f64> = (0..2 * n).map(|i| b[(i % 2) * n + i / 2]).collect();
        supernodal_forward::<2>(sn, &values, &mut w2, n);
        supernodal_backward::<2>(sn, &values, &mut w2, n);
        for (c, alone) in alone.iter().enumerate() {
            let together: Vec<u64> = w2.iter().skip(c).step_by(2).map(|v| v.to_bits()).collect();
            assert_eq!(&together, alone, "{ny}×{nx}: column {c}");
        }
    }
}

/// A right-hand side nonzero on a few cells of one grid row (as the flow's inlet and outlet
/// columns), whose forward substitution passes over the supernodes it does not reach: the
/// answer against the operator (relative residual), nonzero on every cell (the operator of
/// a connected grid has a positive inverse), and with one column or two interleaved the
/// same bits.
#[test]
fn a_right_hand_side_on_one_row_solves_against_the_operator() {
    use crate::flow::substitution::{supernodal_backward, supernodal_forward};
    for (ny, nx, amd) in [(40, 40, false), (64, 64, true), (33, 70, true)] {
        let a = grid_operator(ny, nx, 3 + ny as u64, None);
        let (symbolic, values) = factored(&a, amd);
        let sn = supernodes(&symbolic);
        let n = ny * nx;
        let (fwd, inv) = match symbolic.perm() {
            Some(p) => (p.arrays().0.to_vec(), p.arrays().1.to_vec()),
            None => ((0..n).collect(), (0..n).collect()),
        };
        // Column 0: three cells of the first row; column 1: the whole last row.
        let mut b = vec![vec![0.0; n]; 2];
        for j in [1, nx / 2, nx - 2] {
            b[0][j] = 1.0 + j as f64;
        }
        b[1][(ny - 1) * nx..].fill(2.0);
        let mut both: Vec<f64> = (0..2 * n).map(|i| b[i % 2][fwd[i / 2]]).collect();
        supernodal_forward::<2>(sn, &values, &mut both, n);
        supernodal_backward::<2>(sn, &values, &mut both, n);
        for (c, b) in b.iter().enumerate() {
            let mut w: Vec<f64> = fwd.iter().map(|&q| b[q]).collect();
            supernodal_forward::<1>(sn, &values, &mut w, n);
            supernodal_backward::<1>(sn, &values, &mut w, n);
            let x: Vec<f64> = (0..n).map(|q| w[inv[q]]).collect();
            assert!(
                x.iter().all(|&v| v > 0.0),
                "{ny}×{nx}: a zero or negative entry"
            );
            let rel = relative_residual(&a, &x, b);
            assert!(
                rel < 1e-12,
                "{ny}×{nx}: column {c}: relative residual {rel:e}"
            );
            let alone: Vec<u64> = w.iter().map(|v| v.to_bits()).collect();
            let together: Vec<u64> = both
                .iter()
                .skip(c)
                .step_by(2)
                .map(|v| v.to_bits())
                .collect();
            assert_eq!(together, alone, "{ny}×{nx}: column {c} interleaved");
        }
    }
}

/// A factor stopped at a forced supernode boundary ([`crate::flow::symbolic::Supernodes`]
/// analysed with `split`, [`crate::flow::supernodal::factor_values`] with `stop` there):
/// the boundary is there, and the blocks from it on hold the Schur complement
/// `A₂₂ − A₂₁ A₁₁⁻¹ A₁₂` of the columns before it, against a dense elimination of the same
/// matrix (faer's dense Cholesky of `A₁₁`), to 1e-12 of its largest entry. Splits at the
/// first and the last column, near the end and in the middle; wrapped grids whose face
/// conductances span six decades.
#[test]
fn a_factor_stopped_at_a_split_leaves_the_schur_complement() {
    use crate::flow::supernodal::factor_values;
    use crate::flow::symbolic::Supernodes;
    use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch};
    use faer::Mat;
    for (ny, nx) in [(9, 7), (16, 12)] {
        let a = grid_operator(ny, nx, 5 + nx as u64, None);
        let n = ny * nx;
        let (cp, ri, v) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
        let dense = Mat::<f64>::from_fn(n, n, |i, j| {
            let (lo, hi) = (i.min(j), i.max(j));
            (cp[lo]..cp[lo + 1])
                .find(|&p| ri[p] == hi)
                .map_or(0.0, |p| v[p])
        });
        for split in [0, 1, n / 2, n - 17, n - 1, n] {
            let sym = Supernodes::analyse(n, cp, ri, split).unwrap();
            let sn = sym.layout();
            assert!(
                (0..sn.n_supernodes())
                    .all(|s| sn.supernode_end()[s] <= split || sn.supernode_begin()[s] >= split),
                "{ny}×{nx}: no boundary at {split}"
            );
            let mut values = vec![f64::NAN; sn.len_val()];
            factor_values(sn, a.as_ref(), &mut values, split).unwrap();
            // The Schur complement by dense elimination: `A₂₂ − X Xᵀ`, `X = A₂₁ L₁₁⁻ᵀ`.
            let k = n - split;
            let mut l11 = Mat::<f64>::from_fn(split, split, |i, j| dense[(i, j)]);
            let scratch = cholesky_in_place_scratch::<f64>(split, Par::Seq, Default::default());
            cholesky_in_place(
                l11.as_mut(),
                Default::default(),
                Par::Seq,
                MemStack::new(&mut MemBuffer::new(scratch)),
                Default::default(),
            )
            .unwrap();
            let mut x = Mat::<f64>::from_fn(split, k, |i, j| dense[(i, split + j)]);
            faer::linalg::triangular_solve::solve_lower_triangular_in_place(
                l11.as_ref(),
                x.as_mut(),
                Par::Seq,
            );
            let schur = Mat::<f64>::from_fn(k, k, |i, j| {
                dense[(split + i, split + j)]
                    - (0..split).map(|q| x[(q, i)] * x[(q, j)]).sum::<f64>()
            });
            // The lower triangle of the blocks from the split on.
            let mut got = Mat::<f64>::zeros(k, k);
            for t in 0..sn.n_supernodes() {
                let node = Supernode::of(sn, &values, t);
                if node.start < split {
                    continue;
                }
                for c in 0..node.ncols {
                    let j = node.start + c - split;
                    let col = node.column(c);
                    for (r, &w) in col[c..node.ncols].iter().enumerate() {
                        got[(j + r, j)] = w;
                    }
                    for (&i, &w) in node.pattern.iter().zip(&col[node.ncols..]) {
                        got[(i - split, j)] = w;
                    }
                }
            }
            let scale = (0..k)
                .flat_map(|j| (j..k).map(move |i| (i, j)))
                .map(|(i, j)| schur[(i, j)].abs())
                .fold(0.0, f64::max);
            for j in 0..k {
                for i in j..k {
                    assert!(
                        (got[(i, j)] - schur[(i, j)]).abs() <= 1e-12 * scale,
                        "{ny}×{nx}, split {split}: ({i}, {j}) {} against {}",
                        got[(i, j)],
                        schur[(i, j)]
                    );
                }
            }
        }
    }
}
