//! Which solver [`Solver::Auto`] takes once the factor's symbolic analysis is known: the
//! predicted seconds of the numeric factor and its solves against the multigrid's.
//!
//! Both predictions leave out the work the two paths share (labels, stencil, dead ends, the
//! pressures and rates from the answer) and the ordering and analysis already done. The
//! factor's remaining time follows the multiply-adds on its critical path (the heavier
//! half's, [`Analysis::critical_flops`]); its solves and refinement, which follow its
//! entries, add nothing the fit could tell apart from the flops. The multigrid's setup and
//! iterations follow its unknowns. So the multigrid is taken where the factor needs more
//! than [`MULTIGRID_SECONDS_PER_UNKNOWN`] / [`FACTOR_SECONDS_PER_FLOP`] (19 000)
//! multiply-adds per unknown: gaps with large open regions, whose factor fills most
//! (open gaps, light contact on 1537² and 2049² grids), and not near-threshold or moderate
//! contact gaps, whose tortuous spanning cells fill little.
//!
//! The rates are fixed, fitted on the 2-core machine of `benchmarks/results/flow_auto.md`
//! with both threads: the choice depends on the gap alone, not on the machine or the thread
//! count, so a gap gives the same bits everywhere. A wrong choice costs time only (both
//! answers pass the same checks), and little near the crossover, where the two are close.
//!
//! [`Solver::Auto`]: super::Solver::Auto
//! [`Analysis::critical_flops`]: super::direct::Analysis::critical_flops

/// Seconds per multiply-add on the numeric factor's critical path, its solves included.
pub const FACTOR_SECONDS_PER_FLOP: f64 = 4.0e-11;

/// Seconds per unknown of the multigrid's setup and iterations.
pub const MULTIGRID_SECONDS_PER_UNKNOWN: f64 = 0.76e-6;

/// Predicted seconds of the numeric factor and its solves, `critical_flops` multiply-adds
/// on the factor's critical path.
pub fn factor_seconds(critical_flops: f64) -> f64 {
    FACTOR_SECONDS_PER_FLOP * critical_flops
}

/// Predicted seconds of the multigrid's setup and solve on `unknowns` unknowns at
/// `seconds_per_unknown` ([`MULTIGRID_SECONDS_PER_UNKNOWN`] by default).
pub fn multigrid_seconds(unknowns: usize, seconds_per_unknown: f64) -> f64 {
    seconds_per_unknown * unknowns as f64
}

/// Whether `Auto` takes the multigrid over a factor with `critical_flops` multiply-adds on
/// its critical path, for `unknowns` unknowns at `multigrid_seconds_per_unknown`.
pub fn prefers_multigrid(
    critical_flops: f64,
    unknowns: usize,
    multigrid_seconds_per_unknown: f64,
) -> bool {
    factor_seconds(critical_flops) > multigrid_seconds(unknowns, multigrid_seconds_per_unknown)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_multigrid_is_taken_above_the_crossover_fill() {
        let u = 2_000_000;
        let rate = MULTIGRID_SECONDS_PER_UNKNOWN;
        let prefers = |flops, u| prefers_multigrid(flops, u, rate);
        // Multiply-adds per unknown at which the predictions are equal.
        let even = MULTIGRID_SECONDS_PER_UNKNOWN / FACTOR_SECONDS_PER_FLOP;
        assert!((even - 19_000.0).abs() < 1.0, "{even}");
        assert!(!prefers(0.99 * even * u as f64, u));
        assert!(prefers(1.01 * even * u as f64, u));
        // Monotone: more work on the factor's side takes the multigrid, more unknowns for
        // the multigrid the factor.
        assert!(prefers(2.0 * even * u as f64, u));
        assert!(!prefers(1.01 * even * u as f64, 2 * u));
        // A free multigrid is always taken, a factor without work never.
        assert!(prefers_multigrid(1.0, u, 0.0));
        assert!(!prefers_multigrid(0.0, u, rate));
    }
}
