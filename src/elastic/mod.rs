//! The elastic half-space: the influence kernel of uniform pressure on a grid cell and the
//! FFT operators that apply it to a pressure field.

pub mod kernel;
pub mod memory;
pub mod operator;
pub mod transform;
