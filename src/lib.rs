//! Rust core of leakpath: boundary-element contact of an elastic rough surface against a rigid
//! flat, and the connectivity of the free region between them.
//!
//! Pure Rust; the PyO3 bindings live in `python.rs` only.

pub mod clusters;
pub mod error;
pub mod flow;
pub mod influence;
pub mod nnls;
pub mod operator;
pub mod pk;

mod python;

pub use error::{Error, Result};
