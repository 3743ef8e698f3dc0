//! Rust core of leakpath: boundary-element contact of an elastic rough surface against a rigid
//! flat, and the connectivity of the free region between them.
//!
//! Pure Rust; the PyO3 bindings live in `python.rs` only, behind the `python` feature
//! (default), so `cargo build --no-default-features` has no pyo3 or numpy.

pub mod alloc;
pub mod clusters;
pub mod error;
pub mod flow;
pub mod influence;
pub mod multilevel;
pub mod nnls;
pub mod operator;
pub mod pk;

#[cfg(feature = "python")]
mod python;

pub use error::{Error, Result};
