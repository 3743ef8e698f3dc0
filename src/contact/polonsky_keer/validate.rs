//! Checks of a Polonsky–Keer solve's inputs, before anything is allocated.

use super::{Control, Options, Problem};
use crate::error::{Error, Result};
use crate::grid::check_shape;

pub(crate) fn validate(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<()> {
    let (ny, nx) = (problem.ny, problem.nx);
    check_shape(ny, nx)?;
    let n = ny
        .checked_mul(nx)
        .ok_or_else(|| Error::invalid("heights", "the grid is too large"))?;
    if problem.heights.len() != n {
        return Err(Error::invalid(
            "heights",
            format!(
                "expected {ny} × {nx} = {n} values, got {}",
                problem.heights.len()
            ),
        ));
    }
    if !(problem.dx.is_finite() && problem.dx > 0.0) {
        return Err(Error::invalid(
            "dx",
            format!("must be a positive finite number, got {}", problem.dx),
        ));
    }
    if !(problem.e_star.is_finite() && problem.e_star > 0.0) {
        return Err(Error::invalid(
            "e_star",
            format!("must be a positive finite number, got {}", problem.e_star),
        ));
    }
    match control {
        Control::Approach(d) if !(d.is_finite() && d >= 0.0) => {
            return Err(Error::invalid(
                "approach",
                format!("must be a finite number ≥ 0, got {d}"),
            ));
        }
        Control::MeanPressure(m) if !(m.is_finite() && m > 0.0) => {
            return Err(Error::invalid(
                "mean_pressure",
                format!("must be a positive finite number, got {m}"),
            ));
        }
        _ => {}
    }
    if let Some(cap) = opts.hardness {
        check_hardness(cap)?;
        if let Control::MeanPressure(m) = control {
            if m > cap {
                return Err(Error::invalid(
                    "mean_pressure",
                    format!(
                        "{m} exceeds the hardness {cap}: a perfectly plastic surface carries \
                         at most p̄ = hardness (every point at the hardness)"
                    ),
                ));
            }
        }
    }
    if !(opts.tol.is_finite() && opts.tol > 0.0) {
        return Err(Error::invalid(
            "tol",
            format!("must be a positive finite number, got {}", opts.tol),
        ));
    }
    if let Some(i) = first_non_finite(problem.heights) {
        return Err(Error::invalid(
            "heights",
            format!(
                "must be finite; element ({}, {}) is {}",
                i / nx,
                i % nx,
                problem.heights[i]
            ),
        ));
    }
    if let Some(p0) = initial {
        if p0.len() != n {
            return Err(Error::invalid(
                "initial_pressure",
                format!(
                    "must have the shape of the heights ({ny} × {nx}), got {} values",
                    p0.len()
                ),
            ));
        }
        if let Some(i) = first_non_finite(p0) {
            return Err(Error::invalid(
                "initial_pressure",
                format!(
                    "must be finite; element ({}, {}) is {}",
                    i / nx,
                    i % nx,
                    p0[i]
                ),
            ));
        }
    }
    Ok(())
}

/// The first non-finite element, in row-major order.
fn first_non_finite(v: &[f64]) -> Option<usize> {
    crate::grid::first_cell(v, |_, x| !x.is_finite())
}

/// Reject a hardness that is not a positive number (`+∞` is accepted: no cap).
pub fn check_hardness(hardness: f64) -> Result<()> {
    if hardness.is_nan() || hardness <= 0.0 {
        return Err(Error::invalid(
            "hardness",
            format!("must be a positive number (or None / inf for no cap), got {hardness}"),
        ));
    }
    Ok(())
}
