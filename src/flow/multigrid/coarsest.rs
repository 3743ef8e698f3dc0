//! Dense Cholesky factor of the coarsest level.

use super::rows::Rows;

/// Dense Cholesky factor of the coarsest level (at most a few hundred unknowns).
pub(super) struct DenseCholesky {
    n: usize,
    /// Lower triangle, row-major `n × n`.
    l: Vec<f64>,
}

impl DenseCholesky {
    pub(super) fn new(g: &impl Rows) -> Self {
        let n = g.n();
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            l[i * n + i] = g.diag(i);
            for (j, w) in g.row(i) {
                l[i * n + j as usize] -= w;
            }
        }
        for k in 0..n {
            for m in 0..=k {
                let mut v = l[k * n + m];
                for p in 0..m {
                    v -= l[k * n + p] * l[m * n + p];
                }
                if m == k {
                    // SPD by construction; a pivot lost to round-off (a coarse unknown joined
                    // to the rest and the reservoirs by faces below ε of its own) solves as
                    // decoupled.
                    let dk = g.diag(k);
                    let piv = if v > f64::EPSILON * dk { v } else { dk };
                    l[k * n + k] = piv.sqrt();
                } else {
                    l[k * n + m] = v / l[m * n + m];
                }
            }
        }
        DenseCholesky { n, l }
    }

    #[allow(clippy::needless_range_loop)]
    pub(super) fn solve(&self, b: &[f64], x: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            let mut v = b[k];
            for p in 0..k {
                v -= self.l[k * n + p] * x[p];
            }
            x[k] = v / self.l[k * n + k];
        }
        for k in (0..n).rev() {
            let mut v = x[k];
            for q in k + 1..n {
                v -= self.l[q * n + k] * x[q];
            }
            x[k] = v / self.l[k * n + k];
        }
    }
}
