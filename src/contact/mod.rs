//! Frictionless normal contact of an elastic rough surface against a rigid flat: the solvers.

pub mod kkt;
pub mod lawson_hanson;
pub mod polonsky_keer;
