//! Error-free transformations and the compensated sum of a residual row
//! ([`super::assemble::Stencil::residual_compensated`]).
//!
//! A product's rounding error `a b − fl(a b)` comes in one fused multiply-add where the CPU
//! has one, and from Dekker's splitting (17 operations) where it has not. Both are exact
//! whenever the product and its error are normal doubles; the fused path falls back to the
//! splitting outside that range, so every CPU returns the same bits and the fused one only
//! sooner.

/// A sum carried as a double and its rounding error (Ogita, Rump & Oishi's `Dot2`), with
/// products split by fused multiply-add (`FUSED`) or by Dekker's splitting.
#[derive(Clone, Copy)]
pub(super) struct Compensated<const FUSED: bool> {
    sum: f64,
    pub(super) err: f64,
}

impl<const FUSED: bool> Compensated<FUSED> {
    #[inline(always)]
    pub(super) fn new(v: f64) -> Self {
        Compensated { sum: v, err: 0.0 }
    }

    /// Adds `a b` exactly (to the error of the final rounding).
    #[inline(always)]
    pub(super) fn add_product(&mut self, a: f64, b: f64) {
        let (p, pe) = two_product::<FUSED>(a, b);
        let (s, se) = two_sum(self.sum, p);
        self.sum = s;
        self.err += se + pe;
    }

    /// Adds the face flux `c (x_l − x_k)`, `x = hi + lo` (`dlo = lo_l − lo_k`): the
    /// difference of the high parts split exactly into `s + e` ([`two_sum`]), `c s` added
    /// exactly and `c (e + dlo)` rounded, an error of order `ε² |c (x_l − x_k)|`. One
    /// error-free sum and product per face, not two per part: the row's chain of dependent
    /// sums is a quarter as long for `hi + lo`.
    #[inline(always)]
    pub(super) fn add_face(&mut self, c: f64, hi_l: f64, hi_k: f64, dlo: Option<f64>) {
        let (s, e) = two_sum(hi_l, -hi_k);
        self.add_product(c, s);
        self.err += c * (e + dlo.unwrap_or(0.0));
    }

    /// [`Compensated::add_product`] by the fused multiply-add alone (`FUSED`), for a loop
    /// without branches: `false` when the product left the range where that is exact (the
    /// sum is then not to be kept). A zero factor stays in range while the other is below
    /// `2^900`: both ways give `fl(a b)` and an error of `+0` then. Without `FUSED`, Dekker's
    /// splitting and always `true`.
    #[inline(always)]
    pub(super) fn add_product_in_range(&mut self, a: f64, b: f64) -> bool {
        let (p, pe, in_range) = if FUSED {
            let p = a * b;
            let zero = (a == 0.0) | (b == 0.0);
            let small = a.abs().max(b.abs()) <= FUSED_HIGHEST;
            (p, a.mul_add(b, -p), fused_range(a, b, p) | (zero & small))
        } else {
            let (p, pe) = two_product::<false>(a, b);
            (p, pe, true)
        };
        let (s, se) = two_sum(self.sum, p);
        self.sum = s;
        self.err += se + pe;
        in_range
    }

    /// [`Compensated::add_face`] through [`Compensated::add_product_in_range`].
    #[inline(always)]
    pub(super) fn add_face_in_range(
        &mut self,
        c: f64,
        hi_l: f64,
        hi_k: f64,
        dlo: Option<f64>,
    ) -> bool {
        let (s, e) = two_sum(hi_l, -hi_k);
        let in_range = self.add_product_in_range(c, s);
        self.err += c * (e + dlo.unwrap_or(0.0));
        in_range
    }

    #[inline(always)]
    pub(super) fn value(&self) -> f64 {
        self.sum + self.err
    }
}

/// `a + b = s + e` exactly (Knuth).
#[inline(always)]
pub(super) fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Smallest `|a b|` the fused path splits itself, `2^-900`: from there on the product's
/// error is a normal double and Dekker's partial products cannot underflow, so both paths
/// give it exactly.
const FUSED_LOWEST: f64 = f64::from_bits((1023 - 900) << 52);

/// Largest `|a|`, `|b|` the fused path splits itself, `2^900`: Dekker's `(2^27 + 1) v`
/// overflows from about `2^996`.
const FUSED_HIGHEST: f64 = f64::from_bits((1023 + 900) << 52);

/// `a b = p + e` exactly: by one fused multiply-add (`FUSED`, in the range where Dekker's
/// splitting is exact too) or by Dekker's splitting.
#[inline(always)]
pub(super) fn two_product<const FUSED: bool>(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    if FUSED && fused_range(a, b, p) {
        return (p, a.mul_add(b, -p));
    }
    dekker(a, b, p)
}

/// Whether `p = fl(a b)` lies where the fused multiply-add's error is Dekker's exactly.
#[inline(always)]
fn fused_range(a: f64, b: f64, p: f64) -> bool {
    (FUSED_LOWEST..=f64::MAX).contains(&p.abs()) & (a.abs().max(b.abs()) <= FUSED_HIGHEST)
}

/// The error of `p = fl(a b)` by Dekker's splitting (no fused multiply-add needed).
#[inline(always)]
fn dekker(a: f64, b: f64, p: f64) -> (f64, f64) {
    const SPLIT: f64 = 134_217_729.0; // 2^27 + 1
    let split = |v: f64| {
        let t = SPLIT * v;
        let hi = t - (t - v);
        (hi, v - hi)
    };
    let (ah, al) = split(a);
    let (bh, bl) = split(b);
    (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
}

/// Whether this CPU has a fused multiply-add, checked once (the standard library caches
/// it): the fused path of the compensated sums is taken only then.
#[inline]
pub(super) fn fused() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(target_arch = "aarch64")]
    {
        true
    }
    #[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fused and the split products agree to the bit over the whole range of doubles,
    /// and where the fused path is taken its error is the standard library's `mul_add`
    /// (correctly rounded on every platform, in software where the CPU has no FMA).
    #[test]
    fn fused_and_split_products_agree_to_the_bit() {
        let u = crate::test_support::lcg(0x9e37_79b9_7f4a_7c15, 4 * 200_000);
        let mut fused_taken = 0;
        for w in u.chunks_exact(4) {
            // Mantissas at random, exponents over the whole normal range.
            let a = (1.0 + w[0]) * 2f64.powi((2000.0 * w[1]) as i32 - 1000);
            let b = -(1.0 + w[2]) * 2f64.powi((1000.0 * w[3]) as i32 - 500);
            let (p1, e1) = two_product::<true>(a, b);
            let (p2, e2) = two_product::<false>(a, b);
            assert_eq!(
                (p1.to_bits(), e1.to_bits()),
                (p2.to_bits(), e2.to_bits()),
                "{a} {b}"
            );
            if (FUSED_LOWEST..=f64::MAX).contains(&p1.abs())
                && a.abs().max(b.abs()) <= FUSED_HIGHEST
            {
                fused_taken += 1;
                assert_eq!(e1, a.mul_add(b, -p1));
            }
        }
        assert!(fused_taken > 100_000, "{fused_taken}");
        assert_eq!(FUSED_LOWEST, 2f64.powi(-900));
        assert_eq!(FUSED_HIGHEST, 2f64.powi(900));
    }

    /// A product with a zero factor (either sign) has the error `+0` both ways, the other
    /// factor from subnormal to `2^900`: what lets the lanes of a residual row keep the fused
    /// multiply-add for it. Beyond, Dekker's splitting overflows and the lanes hand over.
    #[test]
    fn a_zero_factor_has_the_error_plus_zero_both_ways() {
        let others = [
            0.0,
            -0.0,
            5e-324,
            -1e-310,
            1e-200,
            0.3,
            -7.0,
            1e270,
            -FUSED_HIGHEST,
        ];
        for z in [0.0f64, -0.0] {
            for &v in &others {
                for (a, b) in [(z, v), (v, z)] {
                    let p = a * b;
                    let fused = a.mul_add(b, -p);
                    let (_, split) = dekker(a, b, p);
                    assert_eq!(fused.to_bits(), 0f64.to_bits(), "{a} {b}");
                    assert_eq!(split.to_bits(), 0f64.to_bits(), "{a} {b}");
                    let mut acc = Compensated::<true>::new(1.0);
                    assert!(acc.add_product_in_range(a, b), "{a} {b}");
                }
            }
            for v in [1e300, -f64::MAX] {
                assert!(!Compensated::<true>::new(1.0).add_product_in_range(z, v));
            }
        }
    }
}
