//! Rust core of leakpath: boundary-element contact of an elastic rough surface against a rigid
//! flat, and the connectivity of the free region between them.
//!
//! Pure Rust; the PyO3 bindings live in `python.rs` only.

pub mod error;
pub mod influence;
pub mod operator;

mod python;

pub use error::{Error, Result};
