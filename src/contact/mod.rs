//! Frictionless normal contact of an elastic rough surface against a rigid flat.
//!
//! [`ContactProblem`] owns the operator (and the dense factor of the exact solvers) and is the
//! one entry point: [`ContactProblem::solve`]`(control, solver, start, options)`. The solvers
//! themselves: [`polonsky_keer`] (constrained conjugate gradients on the FFT operator) and
//! [`lawson_hanson`] (Lawson–Hanson NNLS and its block active-set variant on the dense
//! Cholesky factor of the contact block); both report the [`kkt`] certificate. A cold
//! Polonsky–Keer solve starts from the [`multilevel`] coarse-to-fine pressure. With a hardness
//! `H` the pressure is capped at `p ≤ H` ([`capped`], elastic–perfectly-plastic contact).

pub mod capped;
pub mod kkt;
pub mod lawson_hanson;
pub mod multilevel;
pub mod polonsky_keer;
pub mod problem;

pub use problem::{
    ContactProblem, ContactSolution, Control, SolveOptions, Solver, Start,
    AUTO_ACTIVE_SET_MAX_POINTS,
};
