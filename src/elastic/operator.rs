//! The influence operator `u = C p` on a whole field, by FFT convolution.
//!
//! * Free boundary: the Love kernel table is laid out as an even, zero-padded circulant on a
//!   `Py × Px` grid with `P ≥ 2n − 2` per axis, `P` the smallest 2,3,5-smooth size
//!   ([`crate::grid::padded`]): the kernel is even, so the circular convolution equals the
//!   linear one on the `ny × nx` patch (at `P = 2n − 2` the slot of the largest distance
//!   `n − 1` is shared by `±(n − 1)`, which carry the same value).
//! * Periodic: the half-space stiffness in Fourier space, `û_q = 2 p̂_q / (E* |q|)` for
//!   `q ≠ 0`, `û_0 = 0` (u has zero mean), `q = 2π·(k/L)` rad/length — the convention of Tamaas
//!   and of ContactMechanics' `PeriodicFFTElasticHalfSpace` with zero q = 0 stiffness.
//!
//! The product itself (row FFTs, a fused column pass, zero rows skipped) is
//! [`crate::elastic::transform::Transform`], in `f64` here and in `f32` for the
//! single-precision twin ([`Operator::single`]).

use std::sync::OnceLock;

use rayon::prelude::*;
use rustfft::num_complex::Complex64;

use crate::alloc;
use crate::elastic::kernel::Kernel;
use crate::elastic::transform::{Operator32, Transform};
use crate::error::Result;
use crate::grid::{padded, smooth_size, Boundary};

/// `u = C p` by FFT for an `ny × nx` grid.
pub struct Operator {
    pub ny: usize,
    pub nx: usize,
    pub boundary: Boundary,
    /// Transform sizes (`py = ny`, `px = nx` when periodic).
    pub py: usize,
    pub px: usize,
    /// Plans, kernel spectrum and apply buffer of the product.
    fft: Transform<f64>,
    /// The single-precision twin, built on first use ([`Operator::single`]).
    single: OnceLock<Operator32>,
}

impl Operator {
    /// The free-boundary operator for a Love kernel table; `Error::TooLarge` when its buffers
    /// cannot be allocated.
    pub fn try_free(kernel: &Kernel) -> Result<Self> {
        let (ny, nx) = (kernel.ny, kernel.nx);
        let (py, px) = padded(ny, nx, Boundary::Free);
        let mut op = Self::plan(ny, nx, py, px, Boundary::Free)?;
        // Even circulant layout of K on the padded grid.
        let cells = alloc::checked_cells(py, px, "the padded kernel")?;
        let mut padded_kernel: Vec<f64> =
            alloc::try_zeroed(cells, &format!("the {py} × {px} zero-padded kernel"))?;
        padded_kernel
            .par_chunks_mut(px)
            .enumerate()
            .for_each(|(r, row)| {
                let di = if r < ny {
                    Some(r)
                } else if r > py - ny {
                    Some(py - r)
                } else {
                    None
                };
                if let Some(di) = di {
                    let krow = &kernel.table[di * nx..(di + 1) * nx];
                    row[..nx].copy_from_slice(krow);
                    for dj in 1..nx {
                        row[px - dj] = krow[dj];
                    }
                }
            });
        op.fft.spec = op.full_spectrum(padded_kernel)?;
        Ok(op)
    }

    /// [`Operator::try_free`] for tests, where the sizes are small.
    #[cfg(test)]
    pub fn free(kernel: &Kernel) -> Self {
        Self::try_free(kernel).expect("test operators are small")
    }

    /// [`Operator::try_periodic`] for tests, where the sizes are small.
    #[cfg(test)]
    pub fn periodic(ny: usize, nx: usize, dx: f64, e_star: f64) -> Self {
        Self::try_periodic(ny, nx, dx, e_star).expect("test operators are small")
    }

    /// The periodic operator: `û_q = 2 p̂_q / (E* |q|)`, `û_0 = 0`; `Error::TooLarge` when
    /// its buffers cannot be allocated.
    pub fn try_periodic(ny: usize, nx: usize, dx: f64, e_star: f64) -> Result<Self> {
        let mut op = Self::plan(ny, nx, ny, nx, Boundary::Periodic)?;
        op.fft.spec = op.radial_spectrum(dx, "the stiffness spectrum", |q| {
            if q > 0.0 {
                2.0 / (e_star * q)
            } else {
                0.0
            }
        })?;
        Ok(op)
    }

    /// The inverse of the half-space compliance, `ẑ_q = (E* |q| / 2) ĝ_q`, as a periodic
    /// operator on a zero-padded `Py × Px` grid, `P` the smallest 2,3,5-smooth size `≥ n`
    /// (an FFT of a size with a large prime factor, such as 129 = 3·43, costs several times
    /// more), with the `q = 0` stiffness set to that of the longest wavelength,
    /// `E* q_min / 2`, `q_min = 2π / max(Py, Px)·dx`. It is symmetric positive definite on the
    /// padded grid, so its restriction to any set of points (the contact set) is too: the
    /// Polonsky–Keer preconditioner for both boundaries.
    pub fn inverse_compliance(ny: usize, nx: usize, dx: f64, e_star: f64) -> Result<Self> {
        let (py, px) = (smooth_size(ny), smooth_size(nx));
        let mut op = Self::plan(ny, nx, py, px, Boundary::Periodic)?;
        let q_min = 2.0 * std::f64::consts::PI / (py.max(px) as f64 * dx);
        op.fft.spec = op.radial_spectrum(dx, "the preconditioner spectrum", |q| {
            0.5 * e_star * q.max(q_min)
        })?;
        Ok(op)
    }

    /// `f(|q|)` on the half spectrum of the transform grid, `q = 2π·(k/L)` rad/length with
    /// `L = P·dx`, divided by `Py·Px` (the inverse FFT is unnormalised), in the layout of
    /// [`Transform`]'s spectrum: column-major, rows `0..=Py/2` only (even in the row).
    fn radial_spectrum(
        &self,
        dx: f64,
        what: &str,
        f: impl Fn(f64) -> f64 + Sync,
    ) -> Result<Vec<f64>> {
        let (py, px, pxh, sh) = (self.py, self.px, self.px / 2 + 1, self.py / 2 + 1);
        let norm = 1.0 / (py * px) as f64;
        let two_pi = 2.0 * std::f64::consts::PI;
        let (ly, lx) = (py as f64 * dx, px as f64 * dx);
        let mut spec: Vec<f64> = alloc::try_zeroed(pxh * sh, what)?;
        spec.par_chunks_mut(sh).enumerate().for_each(|(c, col)| {
            let qx = two_pi * c as f64 / lx;
            for (r, v) in col.iter_mut().enumerate() {
                let qy = two_pi * r as f64 / ly;
                *v = f((qx * qx + qy * qy).sqrt()) * norm;
            }
        });
        Ok(spec)
    }

    /// FFT plans and the apply buffer (allocated here, so that `apply` never has to).
    fn plan(ny: usize, nx: usize, py: usize, px: usize, boundary: Boundary) -> Result<Self> {
        Ok(Operator {
            ny,
            nx,
            boundary,
            py,
            px,
            fft: Transform::plan(ny, nx, py, px, Vec::new())?,
            single: OnceLock::new(),
        })
    }

    /// Real part of the 2-D FFT of a real even `py × px` field, divided by `py·px`, in the
    /// layout of [`Transform`]'s spectrum (column-major over the half spectrum, rows
    /// `0..=py/2`: the field is even, so its spectrum is even in the row too).
    fn full_spectrum(&self, mut field: Vec<f64>) -> Result<Vec<f64>> {
        let (py, px, pxh) = (self.py, self.px, self.px / 2 + 1);
        let mut half: Vec<Complex64> =
            alloc::try_zeroed(py * pxh, &format!("the {py} × {pxh} kernel half spectrum"))?;
        half.par_chunks_mut(pxh)
            .zip(field.par_chunks_mut(px))
            .for_each_init(
                || self.fft.r2c.make_scratch_vec(),
                |scratch, (out, inp)| {
                    self.fft
                        .r2c
                        .process_with_scratch(inp, out, scratch)
                        .expect("row FFT lengths are fixed by the plan");
                },
            );
        drop(field);
        let norm = 1.0 / (py * px) as f64;
        let sh = py / 2 + 1;
        let mut spec: Vec<f64> = alloc::try_zeroed(pxh * sh, "the kernel spectrum")?;
        spec.par_chunks_mut(sh).enumerate().for_each_init(
            || {
                (
                    vec![Complex64::new(0.0, 0.0); py],
                    vec![Complex64::new(0.0, 0.0); self.fft.col_fwd.get_inplace_scratch_len()],
                )
            },
            |(buf, scratch), (c, col)| {
                for r in 0..py {
                    buf[r] = half[r * pxh + c];
                }
                self.fft.col_fwd.process_with_scratch(buf, scratch);
                for (v, b) in col.iter_mut().zip(buf.iter()) {
                    *v = b.re * norm;
                }
            },
        );
        Ok(spec)
    }

    /// The real kernel spectrum, divided by `Py·Px`: column-major over the half spectrum, rows
    /// `0..=Py/2` of each column (`(Py/2+1)·(Px/2+1)` values; row `Py − r` equals row `r`).
    pub fn spectrum(&self) -> &[f64] {
        &self.fft.spec
    }

    /// The same product with `f32` FFTs ([`Operator32`]), built on first use and kept;
    /// `Error::TooLarge` when its buffers cannot be allocated.
    pub fn single(&self) -> Result<&Operator32> {
        if let Some(s) = self.single.get() {
            return Ok(s);
        }
        let (ny, nx, py, px) = (self.ny, self.nx, self.py, self.px);
        let src = self.spectrum();
        let mut spec: Vec<f32> = alloc::try_with_capacity(src.len(), "the f32 kernel spectrum")?;
        spec.extend(src.iter().map(|&v| v as f32));
        let built = Transform::plan(ny, nx, py, px, spec)?;
        Ok(self.single.get_or_init(|| built))
    }

    /// `u = C p` for row-major `ny × nx` fields.
    pub fn apply(&self, p: &[f64], u: &mut [f64]) {
        self.fft.apply(p, u);
    }

    /// The product restricted to `S = {k : member(support_k)}`, `u = χ C χ x`
    /// ([`Transform::apply_restricted`]).
    pub fn apply_restricted<M>(&self, x: &[f64], support: &[f64], member: M, u: &mut [f64])
    where
        M: Fn(f64) -> bool + Sync,
    {
        self.fft.apply_restricted(x, support, member, u);
    }
}

/// Dense reference product `u = C p` from the kernel table (O(N²); tests only).
pub fn dense_apply(kernel: &Kernel, p: &[f64]) -> Vec<f64> {
    let n = kernel.ny * kernel.nx;
    (0..n)
        .into_par_iter()
        .map(|a| (0..n).map(|b| kernel.coeff(a, b) * p[b]).sum())
        .collect()
}

/// Tests of a restricted product: `u` from `apply_restricted(p, support, member, u)` equals
/// the dense product of `p` masked to `S = {member(support)}` within `rel` of its largest value
/// on `S`, and is exactly zero off `S`.
#[cfg(test)]
pub fn assert_restricted_is_dense(
    kernel: &Kernel,
    p: &[f64],
    support: &[f64],
    member: impl Fn(f64) -> bool + Copy,
    rel: f64,
    apply_restricted: impl Fn(&[f64], &[f64], &mut [f64]),
) {
    let masked: Vec<f64> = p
        .iter()
        .zip(support)
        .map(|(&x, &s)| if member(s) { x } else { 0.0 })
        .collect();
    let d = dense_apply(kernel, &masked);
    let scale = d.iter().fold(0.0f64, |a, &v| a.max(v.abs()));
    let mut u = vec![f64::NAN; p.len()];
    apply_restricted(p, support, &mut u);
    let (ny, nx) = (kernel.ny, kernel.nx);
    for ((a, b), &s) in u.iter().zip(&d).zip(support) {
        if member(s) {
            assert!((a - b).abs() <= rel * scale, "{ny}x{nx}: {a} vs {b}");
        } else {
            assert_eq!(*a, 0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_support::lcg;

    #[test]
    fn smooth_sizes() {
        assert_eq!(smooth_size(257), 270);
        assert_eq!(smooth_size(8193), 8640);
        assert_eq!(smooth_size(1), 1);
        assert_eq!(smooth_size(7), 8);
        // Free boundary: 2n − 2, so the paper's 2^m + 1 grids transform at powers of two.
        assert_eq!(padded(129, 4097, Boundary::Free), (256, 8192));
        assert_eq!(padded(1, 2, Boundary::Free), (1, 2));
        assert_eq!(padded(100, 3, Boundary::Free), (200, 4));
    }

    #[test]
    fn free_operator_equals_dense_product() {
        // P = 2n − 2 exactly for 9, 5, 13, 17, 33, 2, 3: the largest distance shares its slot.
        let shapes = [
            (9usize, 9usize),
            (8, 8),
            (7, 12),
            (13, 5),
            (1, 6),
            (17, 33),
            (2, 3),
        ];
        for &(ny, nx) in &shapes {
            let ker = Kernel::new(ny, nx, 0.3, 2.0);
            let op = Operator::free(&ker);
            let p = lcg((ny * 100 + nx) as u64, ny * nx);
            let mut u = vec![0.0; ny * nx];
            op.apply(&p, &mut u);
            let d = dense_apply(&ker, &p);
            let scale = d.iter().fold(0.0f64, |a, &v| a.max(v.abs()));
            for (a, b) in u.iter().zip(&d) {
                assert!((a - b).abs() <= 1e-12 * scale, "{ny}x{nx}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn zero_rows_and_restricted_products_equal_the_dense_product() {
        // Rows of p that vanish skip their forward row FFT; apply_restricted computes χ C χ p
        // for the set S = {member(support)} (here a band, as the free set 0 < p < H of a capped
        // solve), skipping rows without a point of S. Oracle: the dense product from the
        // kernel table, of p masked to S.
        for &(ny, nx) in &[(11usize, 9usize), (8, 13)] {
            let ker = Kernel::new(ny, nx, 0.4, 1.3);
            let op = Operator::free(&ker);
            let mut p = lcg((ny * 31 + nx) as u64, ny * nx);
            for i in [0usize, 3, 4, ny - 1] {
                p[i * nx..(i + 1) * nx].fill(0.0);
            }
            let d = dense_apply(&ker, &p);
            let scale = d.iter().fold(0.0f64, |a, &v| a.max(v.abs()));
            let mut u = vec![0.0; ny * nx];
            op.apply(&p, &mut u);
            for (a, b) in u.iter().zip(&d) {
                assert!((a - b).abs() <= 1e-12 * scale, "{ny}x{nx}: {a} vs {b}");
            }
            let mut support = lcg((ny * 5 + nx) as u64, ny * nx);
            support[nx..2 * nx].fill(0.9);
            support[5 * nx..6 * nx].fill(0.0);
            let member = |v: f64| v > 0.2 && v < 0.7;
            assert_restricted_is_dense(&ker, &p, &support, member, 1e-12, |x, s, u| {
                op.apply_restricted(x, s, member, u)
            });
        }
        // The periodic operator of a field with zero rows against its restricted product on
        // every point (zero rows then transformed, to round-off-free zeros): the same values.
        let (ny, nx) = (12usize, 10usize);
        let op = Operator::periodic(ny, nx, 0.5, 2.0);
        let mut p = lcg(5, ny * nx);
        p[2 * nx..5 * nx].fill(0.0);
        let mut u = vec![0.0; ny * nx];
        op.apply(&p, &mut u);
        let mut all = vec![0.0; ny * nx];
        op.apply_restricted(&p, &vec![1.0; ny * nx], |v: f64| v > 0.0, &mut all);
        assert_eq!(u, all);
        // Oracle for the periodic case: superposition of shifted unit responses.
        let mut e0 = vec![0.0; ny * nx];
        e0[0] = 1.0;
        let mut col = vec![0.0; ny * nx];
        op.apply(&e0, &mut col);
        let scale = u.iter().fold(0.0f64, |a, &v| a.max(v.abs()));
        for (a, &ua) in u.iter().enumerate() {
            let (ia, ja) = (a / nx, a % nx);
            let mut want = 0.0;
            for (b, &pb) in p.iter().enumerate() {
                let (ib, jb) = (b / nx, b % nx);
                want += col[((ia + ny - ib) % ny) * nx + (ja + nx - jb) % nx] * pb;
            }
            assert!((ua - want).abs() <= 1e-12 * scale, "{a}: {ua} vs {want}");
        }
    }

    #[test]
    fn periodic_operator_of_a_cosine() {
        // p = cos(2π k x / L) along axis 1 → u = 2 p / (E* q).
        let (ny, nx, dx, e) = (6usize, 16usize, 0.25, 1.7);
        let op = Operator::periodic(ny, nx, dx, e);
        let k = 3.0;
        let lx = nx as f64 * dx;
        let q = 2.0 * std::f64::consts::PI * k / lx;
        let p: Vec<f64> = (0..ny * nx)
            .map(|i| (q * (i % nx) as f64 * dx).cos())
            .collect();
        let mut u = vec![0.0; ny * nx];
        op.apply(&p, &mut u);
        for (a, b) in u.iter().zip(&p) {
            assert!((a - 2.0 * b / (e * q)).abs() < 1e-12);
        }
        // A uniform pressure gives zero displacement (u has zero mean).
        let mut u0 = vec![1.0; ny * nx];
        op.apply(&vec![1.0; ny * nx], &mut u0);
        assert!(u0.iter().all(|v| v.abs() < 1e-14));
    }

    #[test]
    fn periodic_operator_of_a_wave_along_each_axis_odd_and_even() {
        // p = cos(q·x + phase) → u = 2 p / (E* |q|), for waves along axis 0 (rows k and
        // P − k of the spectrum: its stored half and the mirrored one) on odd and even row
        // counts, and along the diagonal.
        let (dx, e) = (0.5, 1.3);
        for &(ny, nx) in &[(9usize, 8usize), (10, 7), (15, 6)] {
            let op = Operator::periodic(ny, nx, dx, e);
            for &(ky, kx) in &[(1usize, 0usize), (2, 0), (ny / 2, 0), (2, 1)] {
                let (qy, qx) = (
                    2.0 * std::f64::consts::PI * ky as f64 / (ny as f64 * dx),
                    2.0 * std::f64::consts::PI * kx as f64 / (nx as f64 * dx),
                );
                let q = (qy * qy + qx * qx).sqrt();
                let p: Vec<f64> = (0..ny * nx)
                    .map(|a| {
                        let (i, j) = ((a / nx) as f64 * dx, (a % nx) as f64 * dx);
                        (qy * i + qx * j + 0.3).cos()
                    })
                    .collect();
                let mut u = vec![0.0; ny * nx];
                op.apply(&p, &mut u);
                for (a, b) in u.iter().zip(&p) {
                    let want = 2.0 * b / (e * q);
                    assert!(
                        (a - want).abs() < 1e-12,
                        "{ny}x{nx} k=({ky},{kx}): {a} vs {want}"
                    );
                }
            }
        }
    }
}
