//! Rust core of leakpath: boundary-element contact of an elastic rough surface against a rigid
//! flat, and the connectivity of the free region between them.
//!
//! Pure Rust; the PyO3 bindings live in `python/` only (one file per area), behind the `python` feature
//! (off by default; maturin turns it on), so `cargo build` and `cargo test` have no pyo3 or numpy.
//! Users reach it through Python; its Rust docs are for its developers and link freely to the
//! private constants and helpers that set each algorithm's behaviour (read them with
//! `cargo doc --document-private-items`).
#![allow(rustdoc::private_intra_doc_links)]

pub mod alloc;
pub mod clusters;
pub mod contact;
pub mod dense_scratch;
pub mod elastic;
pub mod elementary;
pub mod error;
pub mod flow;
pub mod grid;

#[cfg(feature = "python")]
mod python;

#[cfg(test)]
mod test_support;

pub use error::{Error, Result};
