//! The FFT product `u = C p` of a real kernel spectrum on an `ny × nx` field, in the float
//! type `T` of its transforms: `f64` for [`Operator`], `f32` for its single-precision twin
//! ([`Operator::single`]).
//!
//! Real row FFTs on the zero-padded rows, then a fused column pass — gather a block of
//! columns, forward FFT, multiply by the kernel spectrum, inverse FFT, scatter — so only `ny`
//! rows of the half spectrum are ever stored; inverse row FFTs last. Inputs and outputs are
//! `f64` slices, converted in the row passes. In `f32` the product carries a relative error of
//! order `1e-7·log₂ P` of the largest `|u|` (measured against the dense product: below
//! `1e-6`), which serves the early iterations of a contact solve, whose certificates are far
//! above that; rustfft in `f32` runs about twice as fast as in `f64` for the lengths of a
//! padded grid (2048–8192), and the column pass moves half the bytes. Every stage runs on
//! rayon; each output value is computed by the same sequence of operations whatever the
//! thread count.
//!
//! Memory access decides the column pass at 4097² (8192² padded grid; the half spectrum is
//! 134 MB in `f32`, each row 32 KB): a block's gather and scatter go row by row, each row's
//! block of values adjacent; the block's columns are padded apart in the work buffer so that
//! the same row of each does not fall into one L1 set; the half spectrum is asked for huge
//! pages (`alloc::try_filled_huge`), so a pass down the rows does not miss the TLB at every
//! row; and only half of the even kernel spectrum is stored. One `f64` product at 4097²,
//! median of 5 on 2 cores: 0.462–0.491 s column by column, 0.376–0.392 s row by row,
//! 0.338 s with huge pages, 0.334–0.337 s with the pad; the `f32` products of a Polonsky–Keer
//! solve gained more (`benchmarks/results/contact_scale.md`).
//!
//! [`Operator`]: super::operator::Operator
//! [`Operator::single`]: super::operator::Operator::single

use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftNum, FftPlanner};

use crate::alloc;
use crate::error::Result;

/// Columns handled per rayon task in the fused column pass.
const COLUMN_BLOCK: usize = 16;

/// Values of padding between two columns of a block in the column pass's buffer.
const COLUMN_PAD: usize = 8;

/// The float type of a transform: an FFT number that converts from and to `f64`.
pub trait Real: FftNum + Into<f64> {
    /// `v` rounded to this type.
    fn of(v: f64) -> Self;
}

impl Real for f64 {
    #[inline(always)]
    fn of(v: f64) -> f64 {
        v
    }
}

impl Real for f32 {
    #[inline(always)]
    fn of(v: f64) -> f32 {
        v as f32
    }
}

/// The product with `f32` transforms.
pub type Operator32 = Transform<f32>;

/// FFT plans, kernel spectrum and apply buffer of `u = C p` for an `ny × nx` grid
/// transformed on `py × px`.
pub struct Transform<T: Real> {
    ny: usize,
    nx: usize,
    py: usize,
    px: usize,
    /// Half-spectrum width `px/2 + 1`.
    pxh: usize,
    /// Real kernel spectrum, column-major over the half spectrum, already divided by `py·px`
    /// (the inverse transforms are unnormalised). The kernel is even, so its spectrum is even
    /// in the row as well: only rows `0..=py/2` are stored, `spec[c * (py/2 + 1) + r]`, and
    /// row `py − r` reads row `r` (half the bytes each product streams through memory).
    pub(super) spec: Vec<T>,
    pub(super) r2c: Arc<dyn RealToComplex<T>>,
    c2r: Arc<dyn ComplexToReal<T>>,
    pub(super) col_fwd: Arc<dyn Fft<T>>,
    col_inv: Arc<dyn Fft<T>>,
    /// Scratch half spectrum of one apply (`ny × pxh`), kept between calls.
    half: Mutex<Vec<Complex<T>>>,
}

impl<T: Real> Transform<T> {
    /// Plans and the apply buffer (allocated here, so that `apply` never has to) for the
    /// kernel spectrum `spec` (`(py/2+1)·(px/2+1)` values, or empty until the caller sets it);
    /// `Error::TooLarge` when the buffer cannot be allocated.
    pub(super) fn plan(ny: usize, nx: usize, py: usize, px: usize, spec: Vec<T>) -> Result<Self> {
        let pxh = px / 2 + 1;
        let cells = alloc::checked_cells(ny, pxh, "the half spectrum")?;
        let half = alloc::try_filled_huge(
            cells,
            Complex::new(T::zero(), T::zero()),
            &format!("the {ny} × {pxh} half spectrum"),
        )?;
        let mut rp = RealFftPlanner::<T>::new();
        let mut cp = FftPlanner::<T>::new();
        Ok(Transform {
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
        assert_eq!(p.len(), self.ny * self.nx);
        let nx = self.nx;
        self.product(
            u,
            |i, row| load_row(&p[i * nx..(i + 1) * nx], row),
            |_| true,
            store_row,
        );
    }

    /// The product restricted to a point set, `u = χ C χ x` with `χ` the indicator of
    /// `S = {k : member(support_k)}`: `x` is taken as zero off `S` and `u` is set to zero there.
    /// Rows without a point of `S` skip both their row FFTs. This is `C_SS` of a Polonsky–Keer
    /// preconditioner on the contact set, without a masked copy of `x` or of `u`.
    pub fn apply_restricted<M>(&self, x: &[f64], support: &[f64], member: M, u: &mut [f64])
    where
        M: Fn(f64) -> bool + Sync,
    {
        let (ny, nx) = (self.ny, self.nx);
        assert_eq!(x.len(), ny * nx);
        assert_eq!(support.len(), ny * nx);
        let rows: Vec<bool> = support
            .par_chunks(nx)
            .map(|s| s.iter().any(|&v| member(v)))
            .collect();
        self.product(
            u,
            |i, row| {
                if !rows[i] {
                    return false;
                }
                let (xs, ss) = (&x[i * nx..(i + 1) * nx], &support[i * nx..(i + 1) * nx]);
                for ((d, &v), &s) in row.iter_mut().zip(xs).zip(ss) {
                    *d = if member(s) { T::of(v) } else { T::zero() };
                }
                true
            },
            |i| rows[i],
            |i, row, out| {
                let ss = &support[i * nx..(i + 1) * nx];
                for ((d, &v), &s) in out.iter_mut().zip(row).zip(ss) {
                    *d = if member(s) { v.into() } else { 0.0 };
                }
            },
        );
    }

    /// The product on rows: `load(i, row)` writes row `i` of the input into `row[..nx]` and
    /// returns `false` for a zero row (its transform is zero, its forward FFT skipped);
    /// `keep(i)` selects the rows computed (the others are set to zero, their inverse FFT
    /// skipped); `store(i, row, out)` writes row `i` of `u` from the first `nx` transformed
    /// values.
    fn product<L, K, S>(&self, u: &mut [f64], load: L, keep: K, store: S)
    where
        L: Fn(usize, &mut [T]) -> bool + Sync,
        K: Fn(usize) -> bool + Sync,
        S: Fn(usize, &[T], &mut [f64]) + Sync,
    {
        let (ny, nx, py, px, pxh) = (self.ny, self.nx, self.py, self.px, self.pxh);
        assert_eq!(u.len(), ny * nx);
        let zero = Complex::new(T::zero(), T::zero());
        // Rows: real-to-complex on the zero-padded row.
        // The half spectrum is reused across calls: at 4097² a fresh 280 MB buffer per apply
        // costs more in page faults than the FFTs. Every entry is overwritten below.
        let mut guard = self.half.lock().unwrap_or_else(|e| e.into_inner());
        if guard.len() != ny * pxh {
            *guard = vec![zero; ny * pxh];
        }
        let half: &mut [Complex<T>] = &mut guard;
        half.par_chunks_mut(pxh).enumerate().for_each_init(
            || (vec![T::zero(); px], self.r2c.make_scratch_vec()),
            |(row, scratch), (i, out)| {
                if !load(i, &mut row[..nx]) {
                    out.fill(zero);
                    return;
                }
                row[nx..].fill(T::zero());
                self.r2c
                    .process_with_scratch(row, out, scratch)
                    .expect("row FFT lengths are fixed by the plan");
            },
        );
        // Columns: fused forward FFT, multiply, inverse FFT, on blocks of columns. Each task
        // owns a disjoint set of columns of `half`; the raw pointer hands that out without a
        // transpose.
        let n_blocks = pxh.div_ceil(COLUMN_BLOCK);
        let half_ptr = SyncPtr(half.as_mut_ptr());
        // The block's columns lie `ld` apart in `buf`: `py` values of 8 or 16 bytes are a
        // multiple of 4 KiB at the padded sizes (2048–16384), which would put the same row of
        // all the block's columns in one L1 set (8 ways for 16 columns); the pad staggers them.
        let ld = py + COLUMN_PAD;
        (0..n_blocks).into_par_iter().for_each_init(
            || {
                let s = self
                    .col_fwd
                    .get_inplace_scratch_len()
                    .max(self.col_inv.get_inplace_scratch_len());
                (vec![zero; ld * COLUMN_BLOCK], vec![zero; s])
            },
            |(buf, scratch), b| {
                let c0 = b * COLUMN_BLOCK;
                let c1 = (c0 + COLUMN_BLOCK).min(pxh);
                let w = c1 - c0;
                let hp = half_ptr;
                // Row by row: each row's `w` values are adjacent, so a block touches each
                // row's page once (column by column, every value is on another page).
                for r in 0..ny {
                    // SAFETY: columns c0..c1 belong to this task only; r < ny rows exist.
                    let src = unsafe { std::slice::from_raw_parts(hp.0.add(r * pxh + c0), w) };
                    for (t, &v) in src.iter().enumerate() {
                        buf[t * ld + r] = v;
                    }
                }
                let sh = py / 2 + 1;
                for (t, c) in (c0..c1).enumerate() {
                    let col = &mut buf[t * ld..t * ld + py];
                    col[ny..].fill(zero);
                    self.col_fwd.process_with_scratch(col, scratch);
                    let k = &self.spec[c * sh..(c + 1) * sh];
                    let (lo, hi) = col.split_at_mut(sh);
                    for (v, &s) in lo.iter_mut().zip(k) {
                        *v = *v * s;
                    }
                    // Rows sh..py are rows py − sh..1 of the stored half.
                    for (v, &s) in hi.iter_mut().zip(k[1..=py - sh].iter().rev()) {
                        *v = *v * s;
                    }
                    self.col_inv.process_with_scratch(col, scratch);
                }
                for r in 0..ny {
                    // SAFETY: as above.
                    let dst = unsafe { std::slice::from_raw_parts_mut(hp.0.add(r * pxh + c0), w) };
                    for (t, v) in dst.iter_mut().enumerate() {
                        *v = buf[t * ld + r];
                    }
                }
            },
        );
        // Rows: complex-to-real, keep the first nx values.
        u.par_chunks_mut(nx)
            .zip(half.par_chunks_mut(pxh))
            .enumerate()
            .for_each_init(
                || (vec![T::zero(); px], self.c2r.make_scratch_vec()),
                |(row, scratch), (i, (out, inp))| {
                    if !keep(i) {
                        out.fill(0.0);
                        return;
                    }
                    // The DC and Nyquist terms of a real signal are real; drop round-off there.
                    inp[0].im = T::zero();
                    if px % 2 == 0 {
                        inp[pxh - 1].im = T::zero();
                    }
                    self.c2r
                        .process_with_scratch(inp, row, scratch)
                        .expect("row FFT lengths are fixed by the plan");
                    store(i, &row[..nx], out);
                },
            );
    }
}

/// Row `src` of an input field into `row` in the transform's type; `false` if it is zero.
#[inline]
fn load_row<T: Real>(src: &[f64], row: &mut [T]) -> bool {
    if src.iter().all(|&v| v == 0.0) {
        return false;
    }
    for (d, &s) in row.iter_mut().zip(src) {
        *d = T::of(s);
    }
    true
}

/// A transformed row into the output row.
#[inline]
fn store_row<T: Real>(_: usize, row: &[T], out: &mut [f64]) {
    for (d, &s) in out.iter_mut().zip(row) {
        *d = s.into();
    }
}

#[derive(Clone, Copy)]
struct SyncPtr<T>(*mut Complex<T>);
// SAFETY: used only to hand disjoint columns of one buffer to rayon tasks.
unsafe impl<T> Send for SyncPtr<T> {}
unsafe impl<T> Sync for SyncPtr<T> {}

#[cfg(test)]
mod tests {
    use crate::elastic::kernel::Kernel;
    use crate::elastic::operator::{assert_restricted_is_dense, dense_apply, Operator};

    use crate::test_support::lcg;

    fn max_abs(v: &[f64]) -> f64 {
        v.iter().fold(0.0f64, |a, &x| a.max(x.abs()))
    }

    #[test]
    fn free_single_product_equals_dense_product() {
        // Oracle: the dense product from the Love kernel table, to ~1e-6 of the largest |u|.
        for &(ny, nx) in &[(9usize, 9usize), (7, 12), (33, 17), (40, 40), (1, 6)] {
            let ker = Kernel::new(ny, nx, 0.3, 2.0);
            let op = Operator::free(&ker);
            let op32 = op.single().unwrap();
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
            // Restricted to a set S with rows outside it: χ C χ p against the dense product
            // of the masked field.
            let mut support = lcg((ny * 7 + nx) as u64, ny * nx);
            support.iter_mut().for_each(|v| *v -= 0.4);
            if ny > 2 {
                support[nx..2 * nx].fill(-1.0);
            }
            let member = |v: f64| v > 0.0;
            assert_restricted_is_dense(&ker, &p, &support, member, 1e-6, |x, s, u| {
                op32.apply_restricted(x, s, member, u)
            });
        }
    }

    #[test]
    fn periodic_single_product_of_a_cosine() {
        // p = cos(2π k x / L) along each axis → u = 2 p / (E* q), analytic.
        let (ny, nx, dx, e) = (24usize, 32usize, 0.25, 1.7);
        let op = Operator::periodic(ny, nx, dx, e);
        let op32 = op.single().unwrap();
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
        let op32 = op.single().unwrap();
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
