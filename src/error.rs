//! Errors of the Rust core. The bindings map each kind to a Python exception.

use std::fmt;

#[derive(Debug, Clone, PartialEq)]
pub enum Error {
    /// An argument is out of its domain; `name` is the argument as the Python API spells it.
    InvalidArgument { name: &'static str, message: String },
    /// The problem would need more memory than allowed; `bytes` is the estimate. `limit` 0:
    /// no configured limit was exceeded but the allocator refused; `bytes` `u64::MAX`: the
    /// size overflows.
    TooLarge {
        bytes: u64,
        limit: u64,
        what: String,
    },
    /// An iterative method hit its iteration cap.
    NotConverged {
        iterations: usize,
        residual: f64,
        what: String,
    },
    /// The caller asked to stop (Ctrl-C).
    Interrupted,
}

impl Error {
    pub fn invalid(name: &'static str, message: impl Into<String>) -> Self {
        Error::InvalidArgument {
            name,
            message: message.into(),
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::InvalidArgument { name, message } => write!(f, "{name}: {message}"),
            Error::TooLarge { bytes, limit, what } => {
                let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
                if *bytes == u64::MAX {
                    write!(
                        f,
                        "{what} cannot be allocated on any machine; use a smaller grid"
                    )
                } else if *limit == 0 {
                    write!(
                        f,
                        "{what} needs {:.2} GiB and the system refused to allocate it (memory \
                         in use, an address-space ulimit or a container memory limit); use a \
                         smaller grid or free memory",
                        gib(*bytes)
                    )
                } else {
                    write!(
                        f,
                        "{what} needs about {:.2} GiB, more than the memory limit of {:.2} GiB \
                         (memory_limit, by default what this process may still allocate: the \
                         least of the cgroup and ulimit headroom and the available memory, \
                         times a safety fraction); use a smaller grid or pass a larger \
                         memory_limit",
                        gib(*bytes),
                        gib(*limit)
                    )
                }
            }
            Error::NotConverged {
                iterations,
                residual,
                what,
            } => write!(
                f,
                "{what} did not converge in {iterations} iterations (residual {residual:.3e})"
            ),
            Error::Interrupted => write!(f, "interrupted"),
        }
    }
}

impl std::error::Error for Error {}

pub type Result<T> = std::result::Result<T, Error>;
