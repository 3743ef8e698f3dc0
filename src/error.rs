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
                if *bytes == u64::MAX {
                    write!(
                        f,
                        "{what} cannot be allocated on any machine; use a smaller grid"
                    )
                } else if *limit == 0 {
                    write!(
                        f,
                        "{what} needs {} and the system refused to allocate it (memory in use, \
                         an address-space ulimit or a container memory limit); use a smaller \
                         grid or free memory",
                        format_bytes(*bytes)
                    )
                } else {
                    write!(
                        f,
                        "{what} needs about {}, more than the memory limit of {} \
                         (memory_limit, by default what this process may still allocate: the \
                         least of the cgroup and ulimit headroom and the available memory, \
                         times a safety fraction); use a smaller grid or pass a larger \
                         memory_limit",
                        format_bytes(*bytes),
                        format_bytes(*limit)
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

/// `n` bytes in the largest binary unit it reaches (bytes, KiB, MiB, GiB, TiB), three
/// significant digits: the same text as `leakpath._validate.format_bytes`.
pub fn format_bytes(n: u64) -> String {
    const UNITS: [(&str, u64); 4] = [
        ("TiB", 1 << 40),
        ("GiB", 1 << 30),
        ("MiB", 1 << 20),
        ("KiB", 1 << 10),
    ];
    for (unit, size) in UNITS {
        if n >= size {
            return format!("{} {unit}", three_digits(n as f64 / size as f64));
        }
    }
    format!("{n} bytes")
}

/// `x ≥ 1` with three significant digits and no trailing zeros (as Python's `{:.3g}` below
/// 1000; above, the whole number).
fn three_digits(x: f64) -> String {
    let decimals = if x >= 100.0 {
        0
    } else if x >= 10.0 {
        1
    } else {
        2
    };
    let mut s = format!("{x:.decimals$}");
    if s.contains('.') {
        s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_bytes_picks_a_readable_unit() {
        assert_eq!(format_bytes(0), "0 bytes");
        assert_eq!(format_bytes(10), "10 bytes");
        assert_eq!(format_bytes(1023), "1023 bytes");
        assert_eq!(format_bytes(1024), "1 KiB");
        assert_eq!(format_bytes(1536), "1.5 KiB");
        assert_eq!(format_bytes(8 << 20), "8 MiB");
        assert_eq!(format_bytes(3 * (1 << 30) + (1 << 29)), "3.5 GiB");
        assert_eq!(format_bytes(123_456_789), "118 MiB");
        assert_eq!(format_bytes(5 << 40), "5 TiB");
    }

    #[test]
    fn too_large_message_shows_small_sizes_in_bytes() {
        let e = Error::TooLarge {
            bytes: 70_000,
            limit: 10,
            what: "x".into(),
        };
        let text = e.to_string();
        assert!(text.contains("68.4 KiB"), "{text}");
        assert!(text.contains("limit of 10 bytes"), "{text}");
    }
}
