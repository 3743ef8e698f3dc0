//! The smallest and largest gap of the free cells (off the contact mask): what a flow's
//! input checks read before the solve (the round-off band of negative gaps and the floor
//! of open gaps, `leakpath._flow`), in one parallel pass instead of numpy's masked
//! reductions (1.5 ms at 513², 0.2 s at 4097²).

use rayon::prelude::*;

/// Cells per task.
const CHUNK: usize = 1 << 16;

/// `(min, max)` of `gap` over the cells where `contact` is false (all cells without a
/// mask); `(+∞, −∞)` when no cell is free. The values are expected finite (NaN is skipped
/// by `f64::min` and `f64::max`). Minimum and maximum are exact, so the answer does not
/// depend on the order of the pass or the thread count.
pub fn free_gap_extremes(gap: &[f64], contact: Option<&[bool]>) -> (f64, f64) {
    let fold = |(lo, hi): (f64, f64), v: f64| (lo.min(v), hi.max(v));
    let join = |a: (f64, f64), b: (f64, f64)| (a.0.min(b.0), a.1.max(b.1));
    let none = (f64::INFINITY, f64::NEG_INFINITY);
    match contact {
        None => gap
            .par_chunks(CHUNK)
            .map(|g| g.iter().copied().fold(none, fold))
            .reduce(|| none, join),
        Some(c) => {
            assert_eq!(c.len(), gap.len(), "a contact mask of the gap's shape");
            gap.par_chunks(CHUNK)
                .zip(c.par_chunks(CHUNK))
                .map(|(g, c)| {
                    g.iter()
                        .zip(c)
                        .filter(|&(_, &on)| !on)
                        .fold(none, |acc, (&v, _)| fold(acc, v))
                })
                .reduce(|| none, join)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a plain loop over the free cells, on masks with none, some and every cell
    /// in contact, over several chunks and a short last one.
    #[test]
    fn extremes_of_the_free_cells() {
        let n = 3 * CHUNK + 17;
        let g: Vec<f64> = crate::flow::tests::lcg(3, n)
            .iter()
            .map(|&u| 4.0 * u - 1.0)
            .collect();
        for frac in [0.0, 0.3, 1.0] {
            let mask: Vec<bool> = crate::flow::tests::lcg(9, n)
                .iter()
                .map(|&u| u < frac)
                .collect();
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for k in 0..n {
                if !mask[k] {
                    lo = if g[k] < lo { g[k] } else { lo };
                    hi = if g[k] > hi { g[k] } else { hi };
                }
            }
            assert_eq!(
                free_gap_extremes(&g, Some(&mask)),
                (lo, hi),
                "contact {frac}"
            );
        }
        let lo = g.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = g.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!(free_gap_extremes(&g, None), (lo, hi));
        assert_eq!(
            free_gap_extremes(&[], None),
            (f64::INFINITY, f64::NEG_INFINITY)
        );
    }
}
