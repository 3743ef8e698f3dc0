//! The KKT certificate of a contact state, one definition for every solver.
//!
//! For pressures `p ≥ 0` and gaps `g` (`g = u − (Δ − (max h − h))`), relative to a length scale
//! `s` (the height range `h_s = max h − min h`, or the solver's replacement for flat surfaces):
//!
//! ```text
//! kkt = max( −min_i g_i,  max_{p_i > 0} |g_i|,  Σ p_i |g_i| / Σ p_i ) / s
//! ```
//!
//! (the last term is dropped when `Σ p = 0`; the first two are clipped below at 0). It is zero
//! exactly when the state satisfies the complementarity conditions `p ≥ 0, g ≥ 0, p g = 0`.
//! A non-finite gap gives NaN, so an overflowed state never passes a tolerance.
//!
//! Sums run over fixed chunks of [`CHUNK`] points combined in chunk order, so the value does
//! not depend on the thread count; Polonsky–Keer accumulates the same terms in the same order
//! inside its fused passes and reports the identical number.

use rayon::prelude::*;

/// Points per reduction chunk.
pub const CHUNK: usize = 4096;

/// Partial certificate of one chunk.
#[derive(Clone, Copy)]
struct Part {
    min_g: f64,
    max_gc: f64,
    sum_p: f64,
    sum_pg: f64,
    bad: usize,
}

impl Part {
    const ZERO: Part = Part {
        min_g: f64::INFINITY,
        max_gc: 0.0,
        sum_p: 0.0,
        sum_pg: 0.0,
        bad: 0,
    };

    fn merge(self, o: &Part) -> Part {
        Part {
            min_g: self.min_g.min(o.min_g),
            max_gc: self.max_gc.max(o.max_gc),
            sum_p: self.sum_p + o.sum_p,
            sum_pg: self.sum_pg + o.sum_pg,
            bad: self.bad + o.bad,
        }
    }
}

/// The KKT certificate of `(pressure, gap)` relative to `scale` (see the module documentation).
pub fn kkt_certificate(pressure: &[f64], gap: &[f64], scale: f64) -> f64 {
    let parts: Vec<Part> = pressure
        .par_chunks(CHUNK)
        .zip(gap.par_chunks(CHUNK))
        .map(|(pc, gc)| {
            let mut a = Part::ZERO;
            for (&p, &g) in pc.iter().zip(gc) {
                if g < a.min_g {
                    a.min_g = g;
                }
                if !g.is_finite() {
                    a.bad += 1;
                }
                if p > 0.0 {
                    let ag = g.abs();
                    a.sum_p += p;
                    a.sum_pg += p * ag;
                    if ag > a.max_gc {
                        a.max_gc = ag;
                    }
                }
            }
            a
        })
        .collect();
    let a = parts.iter().fold(Part::ZERO, |a, b| a.merge(b));
    if a.bad > 0 {
        return f64::NAN;
    }
    let mut c = (-a.min_g).max(a.max_gc).max(0.0);
    if a.sum_p > 0.0 {
        c = c.max(a.sum_pg / a.sum_p);
    }
    c / scale
}

/// The certificate of a capped state (`0 ≤ p ≤ hardness`, [`crate::contact::capped`]),
/// relative to `scale`:
///
/// ```text
/// kkt = max( max_{p=0} (−g)⁺,  max_{0<p<H} |g|,  max_{p=H} g⁺,  Σ_{0<p<H} p |g| / Σ p ) / s
/// ```
///
/// Plastic points (`p = H`) may have any `g ≤ 0` (the plastic interpenetration). NaN on a
/// non-finite gap. With `hardness = ∞` it is [`kkt_certificate`].
pub fn kkt_certificate_capped(pressure: &[f64], gap: &[f64], hardness: f64, scale: f64) -> f64 {
    let parts: Vec<(f64, f64, f64, usize)> = pressure
        .par_chunks(CHUNK)
        .zip(gap.par_chunks(CHUNK))
        .map(|(pc, gc)| {
            let (mut viol, mut sp, mut spg, mut bad) = (0.0f64, 0.0, 0.0, 0usize);
            for (&p, &g) in pc.iter().zip(gc) {
                if !g.is_finite() {
                    bad += 1;
                }
                if p <= 0.0 {
                    viol = viol.max(-g);
                } else if p >= hardness {
                    sp += p;
                    viol = viol.max(g);
                } else {
                    sp += p;
                    spg += p * g.abs();
                    viol = viol.max(g.abs());
                }
            }
            (viol, sp, spg, bad)
        })
        .collect();
    let (viol, sp, spg, bad) = parts.iter().fold((0.0f64, 0.0, 0.0, 0usize), |a, b| {
        (a.0.max(b.0), a.1 + b.1, a.2 + b.2, a.3 + b.3)
    });
    if bad > 0 {
        return f64::NAN;
    }
    let mut c = viol;
    if sp > 0.0 {
        c = c.max(spg / sp);
    }
    c / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plain serial evaluation of the formula, term by term.
    fn oracle(p: &[f64], g: &[f64], scale: f64) -> f64 {
        let neg = g.iter().map(|&v| -v).fold(0.0f64, f64::max);
        let on = p
            .iter()
            .zip(g)
            .filter(|(&pi, _)| pi > 0.0)
            .map(|(_, &gi)| gi.abs())
            .fold(0.0f64, f64::max);
        let sp: f64 = p.iter().filter(|&&v| v > 0.0).sum();
        let spg: f64 = p
            .iter()
            .zip(g)
            .filter(|(&pi, _)| pi > 0.0)
            .map(|(&pi, &gi)| pi * gi.abs())
            .sum();
        let ratio = if sp > 0.0 { spg / sp } else { 0.0 };
        neg.max(on).max(ratio) / scale
    }

    fn field(n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let u = crate::test_support::lcg(seed, 2 * n);
        let p = u[..n].iter().map(|v| (v - 0.5).max(0.0)).collect();
        let g = u[n..].iter().map(|v| 1e-3 * (v - 0.5)).collect();
        (p, g)
    }

    #[test]
    fn one_chunk_matches_the_serial_formula_bit_for_bit() {
        for seed in 0..5 {
            let (p, g) = field(1000, seed);
            assert_eq!(kkt_certificate(&p, &g, 0.7), oracle(&p, &g, 0.7));
        }
    }

    #[test]
    fn many_chunks_match_the_serial_formula() {
        let (p, g) = field(3 * CHUNK + 17, 9);
        let (a, b) = (kkt_certificate(&p, &g, 1.0), oracle(&p, &g, 1.0));
        assert!((a - b).abs() <= 1e-14 * b, "{a} {b}");
    }

    #[test]
    fn capped_certificate_accepts_plastic_interpenetration_only() {
        let p = [1.0, 0.0, 2.0, 0.5];
        let g = [-0.3, 0.5, 0.0, 0.0];
        assert_eq!(kkt_certificate_capped(&p, &g, 1.0, 1.0), 0.0);
        // A plastic point with an open gap should unload.
        assert_eq!(
            kkt_certificate_capped(&p, &[0.2, 0.5, 0.0, 0.0], 1.0, 1.0),
            0.2
        );
        // No cap: the elastic certificate.
        let q = [1.0, 0.0, 2.0, 0.0];
        let h = [0.0, 0.5, 0.0, 1e-3];
        assert_eq!(
            kkt_certificate_capped(&q, &h, f64::INFINITY, 1.0),
            kkt_certificate(&q, &h, 1.0)
        );
    }

    #[test]
    fn zero_for_a_complementary_state_and_nan_for_overflow() {
        let p = [1.0, 0.0, 2.0, 0.0];
        let g = [0.0, 0.5, 0.0, 1e-3];
        assert_eq!(kkt_certificate(&p, &g, 1.0), 0.0);
        let g = [0.0, f64::INFINITY, 0.0, 1e-3];
        assert!(kkt_certificate(&p, &g, 1.0).is_nan());
        // Interpenetration and gaps under pressure both count.
        assert_eq!(kkt_certificate(&p, &[0.0, -0.25, 0.0, 0.0], 0.5), 0.5);
        assert_eq!(kkt_certificate(&p, &[0.0, 0.0, 0.3, 0.0], 1.0), 0.3);
    }
}
