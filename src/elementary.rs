//! Elementwise elementary functions with the same bits on every CPU.
//!
//! numpy evaluates `power` (also `x ** y` and `x ** 3`), `exp`, `log`, `log10`, `cbrt` and
//! `arctan2` on float64 arrays with vector code chosen at run time: Intel's SVML on CPUs with
//! AVX-512, the C library's scalar functions on the others. The two differ in the last bits
//! of some values, so a surface drawn from one seed had different heights, and every number
//! computed from it different last digits, on an AVX-512 machine than on an AVX2 one. [`apply`]
//! computes every element with one scalar function whatever the CPU and the thread count:
//! the C library's `pow`, `exp`, `log` and `log10` (Rust's `powf`, `exp`, `ln` and `log10`
//! call them; glibc picks among its builds of these by whether the CPU has FMA and AVX2,
//! as the x86-64 CPUs of the last decade do, never by AVX-512), and for `cbrt` the
//! implementation compiled into leakpath itself (Rust's, a port of musl's). The Python side
//! reaches the same bits everywhere through it (`leakpath/_elementary.py`).

use rayon::prelude::*;

/// An elementwise function of [`apply`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Elementary {
    /// `x^y` for the given `y` (C `pow`).
    Power(f64),
    /// `eˣ` (C `exp`).
    Exp,
    /// The natural logarithm (C `log`).
    Ln,
    /// The decimal logarithm (C `log10`).
    Log10,
    /// The cube root (Rust's own `cbrt`, within one ulp).
    Cbrt,
}

impl Elementary {
    /// The function at `x`.
    #[inline]
    pub fn at(self, x: f64) -> f64 {
        match self {
            Elementary::Power(y) => x.powf(y),
            Elementary::Exp => x.exp(),
            Elementary::Ln => x.ln(),
            Elementary::Log10 => x.log10(),
            Elementary::Cbrt => x.cbrt(),
        }
    }
}

/// Elements per task of [`apply`] (each element on its own, so the chunks only set the
/// work's grain).
const CHUNK: usize = 1 << 14;

/// `f` applied to every value in place.
pub fn apply(values: &mut [f64], f: Elementary) {
    values
        .par_chunks_mut(CHUNK)
        .for_each(|c| c.iter_mut().for_each(|v| *v = f.at(*v)));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values whose results are exact in every correctly implemented C library, and the
    /// IEEE special cases, through the parallel map (more values than one chunk).
    #[test]
    fn exact_cases_and_special_values() {
        let mut v: Vec<f64> = (0..3 * CHUNK).map(|k| (k % 7) as f64).collect();
        apply(&mut v, Elementary::Power(2.0));
        assert!(v
            .iter()
            .enumerate()
            .all(|(k, &x)| x == ((k % 7) * (k % 7)) as f64));

        let check = |f: Elementary, x: f64, want: f64| {
            let mut v = vec![x; 3];
            apply(&mut v, f);
            for got in v {
                assert!(
                    got == want || (got.is_nan() && want.is_nan()),
                    "{f:?} at {x}: {got} against {want}"
                );
            }
        };
        check(Elementary::Power(0.5), 0.25, 0.5);
        check(Elementary::Power(-1.0), 4.0, 0.25);
        check(Elementary::Power(-1.8), 0.0, f64::INFINITY);
        check(Elementary::Power(1.5), -1.0, f64::NAN);
        check(Elementary::Exp, 0.0, 1.0);
        check(Elementary::Exp, 1000.0, f64::INFINITY);
        check(Elementary::Exp, f64::NEG_INFINITY, 0.0);
        check(Elementary::Ln, 1.0, 0.0);
        check(Elementary::Ln, 0.0, f64::NEG_INFINITY);
        check(Elementary::Ln, -1.0, f64::NAN);
        check(Elementary::Log10, 1000.0, 3.0);
        check(Elementary::Log10, 1e-300, -300.0);
        check(Elementary::Cbrt, -27.0, -3.0);
        check(Elementary::Cbrt, 8.0, 2.0);
        check(Elementary::Cbrt, f64::NAN, f64::NAN);
    }
}
