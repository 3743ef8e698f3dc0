//! Frictionless normal contact of an elastic rough surface against a rigid flat.
//!
//! [`ContactProblem`] owns the operator (and the dense factor of the exact solvers) and is the
//! one entry point: [`ContactProblem::solve`]`(control, solver, start, options)`. The solvers
//! themselves: [`polonsky_keer`] (constrained conjugate gradients on the FFT operator) and
//! [`lawson_hanson`] (Lawson–Hanson NNLS and its block active-set variant on the updatable
//! Cholesky [`factor`] of the contact block); both report the [`kkt`] certificate. A cold
//! Polonsky–Keer solve starts from the coarse-to-fine pressure of
//! [`polonsky_keer`]'s coarse levels. With a hardness `H` the pressure is capped at `p ≤ H`
//! ([`capped`], elastic–perfectly-plastic contact).

pub mod capped;
pub mod factor;
pub mod kkt;
pub mod lawson_hanson;
pub mod polonsky_keer;
pub mod problem;
pub mod solve;

pub use problem::{
    CoarseCost, Control, Options, Problem, Solution, Solver, Start, AUTO_ACTIVE_SET_MAX_POINTS,
    DEFAULT_TOL,
};
pub use solve::ContactProblem;
