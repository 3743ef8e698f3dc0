//! The influence operator `u = C p` of an [`Operator`] with its FFTs in single precision.
//!
//! The same transform as [`Operator`] — real row FFTs on the zero-padded rows, a fused column
//! pass (gather a block of columns, forward FFT, multiply by the kernel spectrum, inverse FFT,
//! scatter), inverse row FFTs, forward row FFTs of zero rows of `p` skipped — with the kernel
//! spectrum, the half spectrum and every FFT in `f32`. Inputs and outputs stay `f64` slices,
//! converted in the row passes. The result carries a relative error of order `1e-7·log₂ P`
//! of the largest `|u|` (measured against the dense product: below `1e-6`), so it serves the
//! early iterations of a contact solve, whose certificates are far above that; rustfft in
//! `f32` runs about twice as fast as in `f64` for the lengths of a padded grid (2048–8192),
//! and the column pass moves half the bytes. Each output value is computed by the same
//! sequence of operations whatever the thread count.

use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

use crate::alloc;
use crate::elastic::operator::Operator;
use crate::error::Result;

/// Columns handled per rayon task in the fused column pass.
const COLUMN_BLOCK: usize = 8;

/// `u = C p` by `f32` FFTs for the grid and spectrum of an [`Operator`].
pub struct Operator32 {
    ny: usize,
    nx: usize,
    py: usize,
    px: usize,
    pxh: usize,
    /// The operator's real spectrum rounded to `f32`, column-major over the half spectrum.
    spec: Vec<f32>,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
    /// Scratch half spectrum of one apply (`ny × pxh`), kept between calls.
    half: Mutex<Vec<Complex32>>,
}

impl Operator32 {
    /// The single-precision twin of `op`; `Error::TooLarge` when its buffers cannot be
    /// allocated (the spectrum, `Py·(Px/2+1)` `f32`, and the half spectrum,
    /// `ny·(Px/2+1)` complex `f32`: half the bytes of the operator's).
    pub fn try_new(op: &Operator) -> Result<Self> {
        let (ny, nx, py, px) = (op.ny, op.nx, op.py, op.px);
        let pxh = px / 2 + 1;
        let src = op.spectrum();
        let mut spec: Vec<f32> = alloc::try_with_capacity(src.len(), "the f32 kernel spectrum")?;
        spec.extend(src.iter().map(|&v| v as f32));
        let cells = alloc::checked_cells(ny, pxh, "the f32 half spectrum")?;
        let half = alloc::try_filled(
            cells,
            Complex32::new(0.0, 0.0),
            &format!("the {ny} × {pxh} f32 half spectrum"),
        )?;
        let mut rp = RealFftPlanner::<f32>::new();
        let mut cp = FftPlanner::<f32>::new();
        Ok(Operator32 {
            ny,
            nx,
            py,
            px,
            pxh,
            spec,
            r2c: rp.plan_fft_forward(px),
            c2r: rp.plan_fft_inverse(px),
            col_fwd: cp.plan_fft_forward(py),
            col_inv: cp.plan_fft_inverse(py),
            half: Mutex::new(half),
        })
    }

    /// `u = C p` for row-major `ny × nx` fields.
    pub fn apply(&self, p: &[f64], u: &mut [f64]) {
        self.apply_rows(p, u, None);
    }

    /// `u = C p` on the rows `i` with `keep(i)`; `u = 0` on the other rows.
    pub fn apply_on_rows(&self, p: &[f64], u: &mut [f64], keep: &(dyn Fn(usize) -> bool + Sync)) {
        self.apply_rows(p, u, Some(keep));
    }

    fn apply_rows(&self, p: &[f64], u: &mut [f64], keep: Option<&(dyn Fn(usize) -> bool + Sync)>) {
        let (ny, nx, py, px, pxh) = (self.ny, self.nx, self.py, self.px, self.pxh);
        assert_eq!(p.len(), ny * nx);
        assert_eq!(u.len(), ny * nx);
        let zero = Complex32::new(0.0, 0.0);
        let mut guard = self.half.lock().unwrap_or_else(|e| e.into_inner());
        if guard.len() != ny * pxh {
            *guard = vec![zero; ny * pxh];
        }
        let half: &mut [Complex32] = &mut guard;
        // Rows: f64 → f32, real-to-complex on the zero-padded row.
        half.par_chunks_mut(pxh).enumerate().for_each_init(
            || (vec![0.0f32; px], self.r2c.make_scratch_vec()),
            |(row, scratch), (i, out)| {
                let src = &p[i * nx..(i + 1) * nx];
                if src.iter().all(|&v| v == 0.0) {
                    out.fill(zero);
                    return;
                }
                for (d, &s) in row[..nx].iter_mut().zip(src) {
                    *d = s as f32;
                }
                row[nx..].fill(0.0);
                self.r2c
                    .process_with_scratch(row, out, scratch)
                    .expect("row FFT lengths are fixed by the plan");
            },
        );
        // Columns: fused forward FFT, multiply, inverse FFT on blocks of columns, each task
        // owning a disjoint set of columns of `half`.
        let n_blocks = pxh.div_ceil(COLUMN_BLOCK);
        let half_ptr = SyncPtr(half.as_mut_ptr());
        (0..n_blocks).into_par_iter().for_each_init(
            || {
                let s = self
                    .col_fwd
                    .get_inplace_scratch_len()
                    .max(self.col_inv.get_inplace_scratch_len());
                (vec![zero; py * COLUMN_BLOCK], vec![zero; s])
            },
            |(buf, scratch), b| {
                let c0 = b * COLUMN_BLOCK;
                let c1 = (c0 + COLUMN_BLOCK).min(pxh);
                let w = c1 - c0;
                let hp = half_ptr;
                for (t, c) in (c0..c1).enumerate() {
                    let col = &mut buf[t * py..(t + 1) * py];
                    for (r, v) in col[..ny].iter_mut().enumerate() {
                        // SAFETY: column c belongs to this task only; r < ny rows exist.
                        *v = unsafe { *hp.0.add(r * pxh + c) };
                    }
                    col[ny..].fill(zero);
                }
                self.col_fwd
                    .process_with_scratch(&mut buf[..w * py], scratch);
                for (t, c) in (c0..c1).enumerate() {
                    let k = &self.spec[c * py..(c + 1) * py];
                    for (v, &s) in buf[t * py..(t + 1) * py].iter_mut().zip(k) {
                        *v *= s;
                    }
                }
                self.col_inv
                    .process_with_scratch(&mut buf[..w * py], scratch);
                for (t, c) in (c0..c1).enumerate() {
                    for r in 0..ny {
                        // SAFETY: as above.
                        unsafe { *hp.0.add(r * pxh + c) = buf[t * py + r] };
                    }
                }
            },
        );
        // Rows: complex-to-real, keep the first nx values as f64.
        u.par_chunks_mut(nx)
            .zip(half.par_chunks_mut(pxh))
            .enumerate()
            .for_each_init(
                || (vec![0.0f32; px], self.c2r.make_scratch_vec()),
                |(row, scratch), (i, (out, inp))| {
                    if keep.is_some_and(|k| !k(i)) {
                        out.fill(0.0);
                        return;
                    }
                    inp[0].im = 0.0;
                    if px % 2 == 0 {
                        inp[pxh - 1].im = 0.0;
                    }
                    self.c2r
                        .process_with_scratch(inp, row, scratch)
                        .expect("row FFT lengths are fixed by the plan");
                    for (d, &s) in out.iter_mut().zip(&row[..nx]) {
                        *d = s as f64;
                    }
                },
            );
    }
}

#[derive(Clone, Copy)]
struct SyncPtr(*mut Complex32);
// SAFETY: used only to hand disjoint columns of one buffer to rayon tasks.
unsafe impl Send for SyncPtr {}
unsafe impl Sync for SyncPtr {}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::elastic::kernel::Kernel;
    use crate::elastic::operator::dense_apply;

    fn lcg(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0f64, |a, &x| a.max(x.abs()))
    }

    #[test]
    fn free_single_product_equals_dense_product() {
        // Oracle: the dense product from the Love kernel table, to ~1e-6 of the largest |u|.
        for &(ny, nx) in &[(9usize, 9usize), (7, 12), (33, 17), (40, 40), (1, 6)] {
            let ker = Kernel::new(ny, nx, 0.3, 2.0);
            let op = Operator::free(&ker);
            let op32 = Operator32::try_new(&op).unwrap();
            let mut p = lcg((ny * 100 + nx) as u64, ny * nx);
            if ny > 4 {
                p[2 * nx..4 * nx].fill(0.0);
            }
            let mut u = vec![0.0; ny * nx];
            op32.apply(&p, &mut u);
            let d = dense_apply(&ker, &p);
            let scale = max_abs(&d);
            for (a, b) in u.iter().zip(&d) {
                assert!((a - b).abs() <= 1e-6 * scale, "{ny}x{nx}: {a} vs {b}");
            }
            let keep = |i: usize| i % 3 != 1;
            let mut v = vec![f64::NAN; ny * nx];
            op32.apply_on_rows(&p, &mut v, &keep);
            for (k, (a, b)) in v.iter().zip(&d).enumerate() {
                if keep(k / nx) {
                    assert!((a - b).abs() <= 1e-6 * scale, "{ny}x{nx}: {a} vs {b}");
                } else {
                    assert_eq!(*a, 0.0);
                }
            }
        }
    }

    #[test]
    fn periodic_single_product_of_a_cosine() {
        // p = cos(2π k x / L) along each axis → u = 2 p / (E* q), analytic.
        let (ny, nx, dx, e) = (24usize, 32usize, 0.25, 1.7);
        let op = Operator::periodic(ny, nx, dx, e);
        let op32 = Operator32::try_new(&op).unwrap();
        for (k, along_x) in [(3.0, true), (5.0, false)] {
            let (n, l) = if along_x { (nx, nx) } else { (ny, ny) };
            let q = 2.0 * std::f64::consts::PI * k / (l as f64 * dx);
            let p: Vec<f64> = (0..ny * nx)
                .map(|i| {
                    let j = if along_x { i % nx } else { i / nx };
                    let _ = n;
                    (q * j as f64 * dx).cos()
                })
                .collect();
            let mut u = vec![0.0; ny * nx];
            op32.apply(&p, &mut u);
            let want: Vec<f64> = p.iter().map(|&v| 2.0 * v / (e * q)).collect();
            let scale = max_abs(&want);
            for (a, b) in u.iter().zip(&want) {
                assert!((a - b).abs() <= 1e-6 * scale, "{a} vs {b}");
            }
        }
    }

    #[test]
    fn single_product_is_the_same_for_one_and_two_threads() {
        let ker = Kernel::new(37, 29, 0.5, 1.0);
        let op = Operator::free(&ker);
        let op32 = Operator32::try_new(&op).unwrap();
        let p = lcg(9, 37 * 29);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut u = vec![0.0; 37 * 29];
            pool.install(|| op32.apply(&p, &mut u));
            u
        };
        let (a, b) = (run(1), run(2));
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}
