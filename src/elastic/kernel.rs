//! Influence coefficients of the elastic half-space (Love's rectangle solution).
//!
//! Element `(i, j)` is the `dx × dx` square centred on grid point `(i, j)` carrying a
//! uniform pressure. The normal surface displacement at the centre of element `(k, l)`
//! caused by unit pressure on element `(i, j)` depends only on `|k − i|` and `|l − j|`
//! (Johnson, *Contact Mechanics*, eq. 3.25, with `a = b = dx/2`):
//!
//! ```text
//! K(x, y) = 1/(π E*) Σ± f(x ± a, y ± b),   f(X, Y) = X asinh(Y/|X|) + Y asinh(X/|Y|)
//! ```
//!
//! with signs `+ − − +` over the corners `(x+a, y+b), (x+a, y−b), (x−a, y+b), (x−a, y−b)`.
//! The `asinh` form is Love's `ln(Y + √(X²+Y²))` form with the `ln|X|` terms, which cancel
//! over the four corners, removed; it avoids the cancellation of the logarithmic form far
//! from the element. `K(0, 0) = 4·dx·ln(1 + √2)/(π E*)` and `K → dx²/(π E* r)` far away.
//!
//! The kernel table `K[|di|, |dj|]` (ny × nx values) is all that is ever stored: any block
//! `C_PP` of the `N × N` influence matrix is built from it on demand.

use rayon::prelude::*;

use crate::alloc;
use crate::error::Result;

/// `X asinh(Y/|X|) + Y asinh(X/|Y|)`, with `0·asinh(·/0) = 0`.
#[inline]
fn corner(x: f64, y: f64) -> f64 {
    let mut v = 0.0;
    if x != 0.0 {
        v += x * (y / x.abs()).asinh();
    }
    if y != 0.0 {
        v += y * (x / y.abs()).asinh();
    }
    v
}

/// Displacement at offset `(x, y)` from the centre of a `dx × dx` element under unit pressure,
/// for contact modulus `e_star`.
#[inline]
pub fn love_displacement(x: f64, y: f64, dx: f64, e_star: f64) -> f64 {
    let a = 0.5 * dx;
    let s =
        corner(x + a, y + a) - corner(x + a, y - a) - corner(x - a, y + a) + corner(x - a, y - a);
    s / (std::f64::consts::PI * e_star)
}

/// The kernel table `K[|di|, |dj|]`, row-major `ny × nx`: displacement at a centre `di` rows and
/// `dj` columns away from a unit-pressure element.
/// Refused with [`Error::TooLarge`](crate::Error::TooLarge) when the table cannot be allocated.
pub fn try_kernel_table(ny: usize, nx: usize, dx: f64, e_star: f64) -> Result<Vec<f64>> {
    let n = alloc::checked_cells(ny, nx, "the kernel table")?;
    let mut k: Vec<f64> = alloc::try_zeroed(n, &format!("the {ny} × {nx} kernel table"))?;
    k.par_chunks_mut(nx.max(1))
        .enumerate()
        .for_each(|(i, row)| {
            let y = i as f64 * dx;
            for (j, v) in row.iter_mut().enumerate() {
                // The table is symmetric in (x, y) ↔ (y, x); evaluating with x along axis 1 keeps
                // the orientation explicit.
                *v = love_displacement(j as f64 * dx, y, dx, e_star);
            }
        });
    Ok(k)
}

/// The kernel table of the grid coarsened by two (spacing `2 dx`, `ny × nx` values) from the
/// table `fine` of spacing `dx` (`fine_nx` columns, at least `ny` rows and `nx` columns). `K` is
/// homogeneous of degree one, `K_{2dx}(2x, 2y) = 2 K_dx(x, y)`, and every operation of
/// [`love_displacement`] commutes with a factor two, so this is the leading `ny × nx` block of
/// `fine` times two, bit for bit the table [`try_kernel_table`] computes (without its `asinh`
/// evaluations, a fifth of a coarse level's cost at 4097²).
pub fn try_coarsened_table(fine: &[f64], fine_nx: usize, ny: usize, nx: usize) -> Result<Vec<f64>> {
    assert!(nx <= fine_nx && ny * fine_nx <= fine.len());
    let n = alloc::checked_cells(ny, nx, "the kernel table")?;
    let mut k: Vec<f64> = alloc::try_zeroed(n, &format!("the {ny} × {nx} kernel table"))?;
    k.par_chunks_mut(nx.max(1))
        .enumerate()
        .for_each(|(i, row)| {
            let src = &fine[i * fine_nx..i * fine_nx + row.len()];
            for (v, &f) in row.iter_mut().zip(src) {
                *v = 2.0 * f;
            }
        });
    Ok(k)
}

/// [`try_kernel_table`] for tests, where the sizes are small.
#[cfg(test)]
pub fn kernel_table(ny: usize, nx: usize, dx: f64, e_star: f64) -> Vec<f64> {
    try_kernel_table(ny, nx, dx, e_star).expect("test kernel tables are small")
}

/// The kernel table with a given shape and element size.
#[derive(Clone, Debug)]
pub struct Kernel {
    pub ny: usize,
    pub nx: usize,
    pub dx: f64,
    pub e_star: f64,
    pub table: Vec<f64>,
}

impl Kernel {
    /// The Love kernel, refused with [`Error::TooLarge`](crate::Error::TooLarge) when its table cannot be allocated.
    pub fn try_new(ny: usize, nx: usize, dx: f64, e_star: f64) -> Result<Self> {
        Ok(Kernel {
            ny,
            nx,
            dx,
            e_star,
            table: try_kernel_table(ny, nx, dx, e_star)?,
        })
    }

    /// [`Kernel::try_new`] for tests, where the sizes are small.
    #[cfg(test)]
    pub fn new(ny: usize, nx: usize, dx: f64, e_star: f64) -> Self {
        Self::try_new(ny, nx, dx, e_star).expect("test kernels are small")
    }

    /// A kernel from a given table, e.g. the periodic one: the first column of the circulant
    /// influence matrix (the response to unit pressure on element (0, 0)). The circulant is
    /// even, `t[ny − d] = t[d]`, so `coeff` indexes it with `|di|, |dj|` like Love's table.
    pub fn from_table(ny: usize, nx: usize, dx: f64, e_star: f64, table: Vec<f64>) -> Self {
        assert_eq!(table.len(), ny * nx);
        Kernel {
            ny,
            nx,
            dx,
            e_star,
            table,
        }
    }

    /// Influence coefficient between flat indices `a` and `b` of the `ny × nx` grid.
    #[inline]
    pub fn coeff(&self, a: usize, b: usize) -> f64 {
        self.coeff_at((a / self.nx, a % self.nx), (b / self.nx, b % self.nx))
    }

    /// Grid coordinates `(row, column)` of flat indices: the block builders divide once per
    /// point, not once per entry.
    pub fn coords(&self, idx: &[usize]) -> Vec<(usize, usize)> {
        idx.iter().map(|&a| (a / self.nx, a % self.nx)).collect()
    }

    /// Influence coefficient between grid points given by coordinates (see [`Kernel::coords`]).
    #[inline]
    pub fn coeff_at(&self, (ia, ja): (usize, usize), (ib, jb): (usize, usize)) -> f64 {
        self.table[ia.abs_diff(ib) * self.nx + ja.abs_diff(jb)]
    }

    /// The dense block `C_PP` for the flat indices `idx`, column-major `k × k`.
    pub fn block(&self, idx: &[usize]) -> Result<Vec<f64>> {
        self.cross_block(idx, idx)
    }

    /// The block `C_{rows, cols}`, column-major `rows.len() × cols.len()`; refused with
    /// [`crate::Error::TooLarge`] when it cannot be allocated.
    pub fn cross_block(&self, rows: &[usize], cols: &[usize]) -> Result<Vec<f64>> {
        let m = rows.len();
        let what = || format!("a {m} × {} block of influence coefficients", cols.len());
        let len = alloc::checked_cells(m, cols.len(), &what())?;
        let mut out: Vec<f64> = alloc::try_zeroed(len, &what())?;
        let rc = self.coords(rows);
        let fill_col = |(c, col): (usize, &mut [f64])| {
            let cc = (cols[c] / self.nx, cols[c] % self.nx);
            for (v, &rr) in col.iter_mut().zip(&rc) {
                *v = self.coeff_at(rr, cc);
            }
        };
        // Small blocks are filled in the calling thread: waking a second one costs more.
        if m * cols.len() < 1 << 15 {
            out.chunks_mut(m.max(1)).enumerate().for_each(fill_col);
        } else {
            out.par_chunks_mut(m.max(1)).enumerate().for_each(fill_col);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn self_coefficient_is_closed_form() {
        for &(dx, e) in &[(1.0, 1.0), (0.01, 2.5), (3.7e-6, 210e9)] {
            let k = kernel_table(4, 4, dx, e);
            let exact = 4.0 * dx * (1.0 + 2f64.sqrt()).ln() / (PI * e);
            assert!(
                ((k[0] - exact) / exact).abs() < 1e-14,
                "{} vs {}",
                k[0],
                exact
            );
        }
    }

    #[test]
    fn coarsened_table_is_the_table_of_twice_the_spacing_bit_for_bit() {
        // Oracle: the table evaluated afresh at spacing 2 dx (the coarse level of a coarse
        // start), for spacings that are not powers of two and moduli of any size.
        for &(dx, e) in &[
            (0.3, 1.0),
            (1.0 / 4097.0, 2.5),
            (3.7e-6, 210e9),
            (7.0, 1e-3),
        ] {
            let (fy, fx) = (17usize, 23usize);
            let fine = kernel_table(fy, fx, dx, e);
            for &(ny, nx) in &[(9usize, 12usize), (17, 23), (1, 5)] {
                let coarse = try_coarsened_table(&fine, fx, ny, nx).unwrap();
                assert_eq!(
                    coarse,
                    kernel_table(ny, nx, 2.0 * dx, e),
                    "dx {dx}, {ny}x{nx}"
                );
            }
        }
    }

    #[test]
    fn far_field_is_point_load() {
        let (dx, e) = (0.5, 3.0);
        let k = kernel_table(64, 64, dx, e);
        // r = 50 dx along an axis, along the diagonal-ish direction (30, 40).
        for &(i, j) in &[(0usize, 50usize), (50, 0), (30, 40), (40, 30)] {
            let r = ((i * i + j * j) as f64).sqrt() * dx;
            let point = dx * dx / (PI * e * r);
            let rel = (k[i * 64 + j] - point).abs() / point;
            assert!(rel < 1e-3, "({i},{j}): rel {rel}");
        }
    }

    #[test]
    fn table_is_symmetric_and_decreasing() {
        let k = kernel_table(20, 20, 1.0, 1.0);
        for i in 0..20 {
            for j in 0..20 {
                assert!((k[i * 20 + j] - k[j * 20 + i]).abs() <= 1e-15 * k[0]);
                if j + 1 < 20 {
                    assert!(k[i * 20 + j + 1] < k[i * 20 + j]);
                }
            }
        }
    }

    #[test]
    fn block_is_symmetric() {
        let ker = Kernel::new(7, 9, 1.0, 1.0);
        let idx = [0usize, 5, 17, 40, 62];
        let b = ker.block(&idx).unwrap();
        for r in 0..5 {
            for c in 0..5 {
                assert_eq!(b[r + 5 * c], b[c + 5 * r]);
            }
            assert_eq!(b[r + 5 * r], ker.table[0]);
        }
    }

    #[test]
    fn rectangular_centre_value_matches_quadrature() {
        // Independent check: integrate the point-load Green's function 1/(π E* r) over a
        // distant element by a fine midpoint rule.
        let (dx, e) = (1.0, 1.0);
        let (x0, y0) = (3.0, 2.0);
        let n = 400;
        let h = dx / n as f64;
        let mut s = 0.0;
        for a in 0..n {
            for b in 0..n {
                let x = -0.5 * dx + (a as f64 + 0.5) * h;
                let y = -0.5 * dx + (b as f64 + 0.5) * h;
                s += h * h / (PI * e * ((x0 - x).powi(2) + (y0 - y).powi(2)).sqrt());
            }
        }
        let v = love_displacement(x0, y0, dx, e);
        assert!(((v - s) / s).abs() < 1e-6, "{v} vs {s}");
    }
}
