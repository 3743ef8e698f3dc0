//! The packing scratch of faer's dense matrix products, and a check before a thread first
//! needs it.
//!
//! faer's dense kernels (the products inside the active-set Cholesky updates and the
//! supernodal flow factor) pack their operands into a per-thread buffer that the product
//! library allocates on a thread's first large product and keeps for the thread's life. Its
//! size does not depend on the problem but on the CPU: two times the last-level cache the
//! CPU *reports* (as the library reads it: Linux's `/sys/devices/system/cpu/*/cache`, scaled
//! by its sharing and by the physical core count). A 2-core AMD EPYC guest reports 32 MiB
//! (64 MiB of scratch per thread); some Intel Xeon guests report 260 MiB (520 MiB per thread).
//! That allocation is infallible: when an address-space limit (`ulimit -v`) leaves no room,
//! the process aborts.
//!
//! [`ensure`] makes this a refusal instead: before the first large dense product on a thread
//! (the calling thread, and with a parallel product every thread of the current pool), it
//! asks the allocator for the same number of bytes *fallibly*, releases them, and at once runs
//! one small product, which makes the library allocate its buffer while the room is known to
//! be there. A thread passes this once; later calls cost a flag test (and, for a pool, one
//! broadcast).
//!
//! On x86-64 with AVX2+FMA or AVX-512 the products come from `private-gemm-x86`, whose
//! sizing [`bytes_per_thread`] reproduces; on other CPUs from `gemm`, whose buffers are
//! smaller (the L2 cache and blocks of the operands), for which the same figure is an upper
//! bound.

use std::cell::Cell;
use std::path::Path;
use std::sync::OnceLock;

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par};

use crate::error::{Error, Result};

/// Products of at most this many multiply-adds (`m·n·k`) need no scratch: faer runs them
/// with an unpacked kernel (its `NANO_GEMM_THRESHOLD`, 16³).
pub const UNPACKED_PRODUCT: usize = 16 * 16 * 16;

/// Cache sizes the product library assumes when the CPU reports none or less (x86-64:
/// 32 KiB, 256 KiB, 2 MiB for L1, L2, L3).
const DEFAULT_CACHE: [usize; 3] = [32 << 10, 256 << 10, 2 << 20];

const PAGE: usize = 4096;

/// Bytes of the per-thread packing scratch of faer's dense products on this CPU: two buffers
/// of the last-level cache size each, in 4 KiB pages, with one page of rounding per buffer.
pub fn bytes_per_thread() -> u64 {
    static BYTES: OnceLock<u64> = OnceLock::new();
    *BYTES.get_or_init(|| {
        let l3 = reported_cache_bytes()[2];
        (2 * (l3.div_ceil(PAGE) + 1) * PAGE) as u64
    })
}

/// The L1, L2, L3 data-cache bytes as the product library reads them, with its floors:
/// each level at least its default and at least four times the level below.
pub fn reported_cache_bytes() -> [usize; 3] {
    let mut c = linux_sysfs_caches(Path::new("/sys/devices/system/cpu"))
        .or_else(lscpu_caches)
        .unwrap_or(DEFAULT_CACHE);
    c[0] = c[0].max(DEFAULT_CACHE[0]);
    c[1] = c[1].max(DEFAULT_CACHE[1]).max(c[0].saturating_mul(4));
    c[2] = c[2].max(DEFAULT_CACHE[2]).max(c[1].saturating_mul(4));
    c
}

/// Cache sizes from `cpu*/cache/index*` under `root`: for each level, the last data or
/// unified cache seen (when its line is not shorter), its size divided by the CPUs sharing
/// it; then every level times the L1's sharing count, and the L3 times the physical cores.
/// `None` when any file cannot be read (the library then asks `lscpu`).
fn linux_sysfs_caches(root: &Path) -> Option<[usize; 3]> {
    let mut bytes = [0usize; 3];
    let mut line = [64usize; 3];
    let mut l1_shared = 1usize;
    for cpu in std::fs::read_dir(root).ok()? {
        let cpu = cpu.ok()?.path();
        let is_cpu = cpu
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n.starts_with("cpu"));
        let cache = cpu.join("cache");
        if !is_cpu || !cache.is_dir() {
            continue;
        }
        for index in std::fs::read_dir(cache).ok()? {
            let index = index.ok()?.path();
            let is_index = index
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("index"));
            if !is_index || !index.is_dir() {
                continue;
            }
            let Some(entry) = read_cache_index(&index)? else {
                continue;
            };
            if entry.level == 1 {
                l1_shared = entry.shared;
            }
            if (1..=3).contains(&entry.level) && entry.line >= line[entry.level - 1] {
                line[entry.level - 1] = entry.line;
                bytes[entry.level - 1] = entry.bytes / entry.shared.max(1);
            }
        }
    }
    for b in &mut bytes {
        *b = b.saturating_mul(l1_shared);
    }
    bytes[2] = bytes[2].saturating_mul(num_cpus::get_physical());
    Some(bytes)
}

struct CacheIndex {
    level: usize,
    bytes: usize,
    line: usize,
    shared: usize,
}

/// One `index*` directory: `Some(None)` for an instruction cache or an entry that does not
/// parse (skipped), `None` when a file cannot be read.
fn read_cache_index(dir: &Path) -> Option<Option<CacheIndex>> {
    let mut entry = CacheIndex {
        level: 0,
        bytes: 0,
        line: 64,
        shared: 0,
    };
    for file in std::fs::read_dir(dir).ok()? {
        let path = file.ok()?.path();
        let text = std::fs::read_to_string(&path).ok()?;
        let text = text.trim();
        let parsed = match path.file_name().and_then(|n| n.to_str()).unwrap_or("") {
            "type" if !matches!(text, "Data" | "Unified") => return Some(None),
            "level" => text.parse().map(|v| entry.level = v).ok(),
            "coherency_line_size" => text.parse().map(|v| entry.line = v).ok(),
            "size" => parse_size(text).map(|v| entry.bytes = v),
            "shared_cpu_list" => cpu_count(text).map(|v| entry.shared = v),
            _ => Some(()),
        };
        if parsed.is_none() {
            return Some(None);
        }
    }
    Some(Some(entry))
}

/// `"32768K"`, `"1M"`, `"1G"` or a plain byte count.
fn parse_size(text: &str) -> Option<usize> {
    let (digits, unit) = match text.as_bytes().last()? {
        b'K' => (&text[..text.len() - 1], 1 << 10),
        b'M' => (&text[..text.len() - 1], 1 << 20),
        b'G' => (&text[..text.len() - 1], 1 << 30),
        _ => (text, 1),
    };
    digits.parse::<usize>().ok()?.checked_mul(unit)
}

/// CPUs in a list such as `"0-3,8,10-11"`.
fn cpu_count(text: &str) -> Option<usize> {
    let mut n = 0usize;
    for item in text.split(',') {
        match item.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (a.parse::<usize>().ok()?, b.parse::<usize>().ok()?);
                n += (b + 1).checked_sub(a)?;
            }
            None => n += 1,
        }
    }
    Some(n)
}

/// `lscpu -B -C=type,level,ways,coherency-size,one-size`: the library's second source.
fn lscpu_caches() -> Option<[usize; 3]> {
    let out = std::process::Command::new("lscpu")
        .args(["-B", "-C=type,level,ways,coherency-size,one-size"])
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let mut c = DEFAULT_CACHE;
    for row in String::from_utf8(out.stdout).ok()?.lines().skip(1) {
        let f: Vec<&str> = row.split_whitespace().collect();
        if f.len() >= 5 && matches!(f[0], "Data" | "Unified") {
            if let (Ok(level @ 1..=3), Ok(size)) = (f[1].parse::<usize>(), f[4].parse()) {
                c[level - 1] = size;
            }
        }
    }
    Some(c)
}

thread_local! {
    /// This thread has its product scratch (it passed [`ensure_here`]).
    static READY: Cell<bool> = const { Cell::new(false) };
}

/// Makes sure every thread that a product with parallelism `par` may run on has its packing
/// scratch: the calling thread, and for `Par::Rayon` every thread of the current pool.
/// `Error::TooLarge` (nothing aborted) when the system cannot provide it.
pub fn ensure(par: Par) -> Result<()> {
    ensure_here()?;
    if let Par::Rayon(_) = par {
        rayon::broadcast(|_| ensure_here())
            .into_iter()
            .collect::<Result<Vec<()>>>()?;
    }
    Ok(())
}

fn ensure_here() -> Result<()> {
    if READY.with(Cell::get) {
        return Ok(());
    }
    let bytes = bytes_per_thread();
    let mut probe: Vec<u8> = Vec::new();
    if probe.try_reserve_exact(bytes as usize).is_err() {
        let l3 = reported_cache_bytes()[2];
        return Err(Error::TooLarge {
            bytes,
            limit: 0,
            what: format!(
                "the packing scratch of the dense matrix products on one thread (twice the \
                 {:.0} MiB last-level cache this CPU reports; solver='polonsky-keer' needs none)",
                l3 as f64 / (1u64 << 20) as f64
            ),
        });
    }
    drop(probe);
    // A product just above the unpacked size: the library allocates its buffer now, into
    // the room just seen free.
    let a = Mat::<f64>::from_fn(32, 32, |i, j| (i + j) as f64);
    let mut c = Mat::<f64>::zeros(32, 32);
    matmul(
        c.as_mut(),
        Accum::Replace,
        a.as_ref(),
        a.as_ref(),
        1.0,
        Par::Seq,
    );
    READY.with(|r| r.set(true));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, files: &[(&str, &str)]) {
        std::fs::create_dir_all(dir).unwrap();
        for (name, text) in files {
            std::fs::write(dir.join(name), format!("{text}\n")).unwrap();
        }
    }

    /// A two-CPU sysfs tree: private L1d/L1i/L2 per CPU, one L3 shared by both.
    fn fake_tree(l3: &str) -> std::path::PathBuf {
        let root = std::env::temp_dir().join(format!(
            "leakpath-cpu-{}-{}",
            std::process::id(),
            l3.replace(|c: char| !c.is_ascii_alphanumeric(), "")
        ));
        let _ = std::fs::remove_dir_all(&root);
        for cpu in 0..2 {
            let c = root.join(format!("cpu{cpu}/cache"));
            let own = cpu.to_string();
            let idx = |t: &'static str, level: &'static str, size: &'static str, sh: &str| {
                let sh = sh.to_string();
                move |dir: &Path| {
                    write(
                        dir,
                        &[
                            ("type", t),
                            ("level", level),
                            ("size", size),
                            ("shared_cpu_list", &sh),
                            ("coherency_line_size", "64"),
                            ("ways_of_associativity", "8"),
                        ],
                    )
                }
            };
            idx("Data", "1", "32K", &own)(&c.join("index0"));
            idx("Instruction", "1", "32K", &own)(&c.join("index1"));
            idx("Unified", "2", "1024K", &own)(&c.join("index2"));
            let l3: &'static str = Box::leak(l3.to_string().into_boxed_str());
            idx("Unified", "3", l3, "0-1")(&c.join("index3"));
        }
        std::fs::create_dir_all(root.join("cpufreq")).unwrap();
        root
    }

    #[test]
    fn sysfs_sizes_follow_the_libraries_reading() {
        let phys = num_cpus::get_physical();
        let root = fake_tree("266240K");
        let c = linux_sysfs_caches(&root).unwrap();
        assert_eq!(c[0], 32 << 10);
        assert_eq!(c[1], 1 << 20);
        // 260 MiB shared by two CPUs, times the physical cores.
        assert_eq!(c[2], (260 << 20) / 2 * phys);
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn sizes_and_cpu_lists_parse() {
        assert_eq!(parse_size("32K"), Some(32 << 10));
        assert_eq!(parse_size("2M"), Some(2 << 20));
        assert_eq!(parse_size("1G"), Some(1 << 30));
        assert_eq!(parse_size("4096"), Some(4096));
        assert_eq!(parse_size("x"), None);
        assert_eq!(cpu_count("0-3,8,10-11"), Some(7));
        assert_eq!(cpu_count("5"), Some(1));
        assert_eq!(cpu_count("3-1"), None);
    }

    #[test]
    fn scratch_is_at_least_twice_the_floor_and_ensure_passes_here() {
        assert!(bytes_per_thread() >= 2 * DEFAULT_CACHE[2] as u64);
        ensure(Par::Seq).unwrap();
        assert!(READY.with(Cell::get));
        ensure(Par::rayon(2)).unwrap();
    }
}
