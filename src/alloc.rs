//! Fallible allocation of the large buffers.
//!
//! A failed `vec![0.0; n]` aborts the process ("memory allocation of … bytes failed"), which
//! takes the user's Python session with it. Every buffer whose size grows with the grid or
//! the contact set is allocated here instead, and a refusal by the allocator (an address-space
//! or cgroup limit, or no memory left) becomes [`Error::TooLarge`] with what was being
//! allocated. Sizes come from user input, so the byte count is computed with checked
//! arithmetic first: an impossible size is refused the same way, before asking the allocator.

use std::alloc::{alloc_zeroed, Layout};

use rustfft::num_complex::Complex64;

use crate::error::{Error, Result};

/// Element types whose all-zero bit pattern is the value zero, so a zeroed allocation is a
/// valid, initialised buffer.
///
/// # Safety
/// Implement only for types for which all-zero bytes are a valid value.
pub unsafe trait Zeroed: Copy {}
// SAFETY: all-zero bytes are 0.0, 0, false and 0 + 0i respectively.
unsafe impl Zeroed for f64 {}
unsafe impl Zeroed for u32 {}
unsafe impl Zeroed for u64 {}
unsafe impl Zeroed for usize {}
unsafe impl Zeroed for bool {}
unsafe impl Zeroed for Complex64 {}

/// Bytes of `n` values of `T`, or `Error::TooLarge` when the count overflows.
pub fn bytes_of<T>(n: usize, what: &str) -> Result<u64> {
    n.checked_mul(std::mem::size_of::<T>())
        .filter(|&b| b <= isize::MAX as usize)
        .map(|b| b as u64)
        .ok_or_else(|| overflow(what))
}

/// `a · b`, or `Error::TooLarge` naming `what` when it overflows (grid sizes from user input).
pub fn checked_cells(a: usize, b: usize, what: &str) -> Result<usize> {
    a.checked_mul(b).ok_or_else(|| overflow(what))
}

fn overflow(what: &str) -> Error {
    Error::TooLarge {
        bytes: u64::MAX,
        limit: isize::MAX as u64,
        what: format!("{what} (its size overflows the address space)"),
    }
}

/// A zero-filled `Vec` of `n` values, or `Error::TooLarge` when the allocator refuses.
/// Zeroed pages come straight from the kernel (`calloc`), as with `vec![0.0; n]`.
pub fn try_zeroed<T: Zeroed>(n: usize, what: &str) -> Result<Vec<T>> {
    let bytes = bytes_of::<T>(n, what)?;
    if n == 0 || std::mem::size_of::<T>() == 0 {
        return Ok(Vec::new());
    }
    let layout = Layout::array::<T>(n).map_err(|_| overflow(what))?;
    // SAFETY: the layout has a non-zero size; a non-null result is an allocation of `n`
    // zeroed `T` with `T`'s alignment from the global allocator, which is what `Vec` frees,
    // and all-zero bytes are a valid `T` (`Zeroed`).
    unsafe {
        let ptr = alloc_zeroed(layout) as *mut T;
        if ptr.is_null() {
            return Err(refused(bytes, what));
        }
        Ok(Vec::from_raw_parts(ptr, n, n))
    }
}

/// `vec![0.0; n]` with its pages faulted in here, zeros written by every thread in fixed
/// chunks. A `calloc`ed buffer is faulted in page by page wherever it is first written, and
/// inside a solver's parallel loops each fault stalls one thread while the other waits at
/// the loop's end (docs/flow.md, "Fresh pages", has the flow's figures at 4097²).
pub fn zeroed_now(n: usize) -> Vec<f64> {
    let mut v: Vec<f64> = Vec::with_capacity(n);
    write_zeros(&mut v.spare_capacity_mut()[..n]);
    // SAFETY: every one of the `n` values of the capacity was written just above.
    unsafe { v.set_len(n) };
    v
}

/// Zeros written into `values` by every thread, in fixed chunks.
fn write_zeros(values: &mut [std::mem::MaybeUninit<f64>]) {
    use rayon::prelude::*;
    values
        .par_chunks_mut(1 << 16)
        .for_each(|c| c.iter_mut().for_each(|e| _ = e.write(0.0)));
}

/// Zeroed `f64` vectors made ahead of their use by a thread of their own, started where the
/// caller's work leaves a core idle (a sequential stretch): their page faults and zeroing
/// are then off the critical path. Taken by length, each once; a length not made ahead (or
/// all of them, when the system refuses the thread) is made by [`zeroed_now`] when taken.
pub struct ZeroedAhead {
    pending: Option<std::thread::JoinHandle<Vec<Vec<f64>>>>,
    ready: Vec<Vec<f64>>,
}

impl ZeroedAhead {
    /// Nothing made ahead: every [`ZeroedAhead::take`] is a [`zeroed_now`].
    pub fn none() -> Self {
        ZeroedAhead {
            pending: None,
            ready: Vec::new(),
        }
    }

    /// Starts making zeroed vectors of the lengths `lens`, on one thread, in order.
    pub fn start(lens: Vec<usize>) -> Self {
        if lens.iter().all(|&n| n == 0) {
            return Self::none();
        }
        let made = std::thread::Builder::new()
            .name("leakpath-zeroed-ahead".into())
            .spawn(move || {
                lens.into_iter()
                    .map(|n| {
                        // Written, not `calloc`ed: the point is to fault the pages in here.
                        let mut v = Vec::with_capacity(n);
                        v.resize(n, 0.0);
                        v
                    })
                    .collect()
            });
        ZeroedAhead {
            pending: made.ok(),
            ready: Vec::new(),
        }
    }

    /// A zeroed vector of length `n`: one made ahead, else [`zeroed_now`]`(n)`.
    pub fn take(&mut self, n: usize) -> Vec<f64> {
        self.wait();
        match self.ready.iter().position(|v| v.len() == n) {
            Some(k) => self.ready.swap_remove(k),
            None => zeroed_now(n),
        }
    }

    /// Vectors made ahead and not taken (after waiting for them).
    pub fn left(&mut self) -> usize {
        self.wait();
        self.ready.len()
    }

    fn wait(&mut self) {
        if let Some(h) = self.pending.take() {
            // A thread that panicked made nothing usable: its vectors are made on demand.
            if let Ok(made) = h.join() {
                self.ready.extend(made);
            }
        }
    }
}

impl Drop for ZeroedAhead {
    /// Joins the thread: its vectors are not left being made after the caller is done.
    fn drop(&mut self) {
        self.wait();
    }
}

/// Zeroed `f64` vectors of one length whose pages are faulted in by threads that would
/// otherwise wait: a parallel stage whose parts end at different times hands the thread that
/// finished first to [`ZeroedByIdle::work_while`] until the others are done. A fresh page
/// costs microseconds on a virtual machine (docs/flow.md, "A first call stage by stage"),
/// so vectors made there are taken later without those faults on the critical path.
/// Whatever part of a vector no idle thread reached is zeroed when it is taken; a vector
/// not made ahead is [`zeroed_now`].
pub struct ZeroedByIdle {
    len: usize,
    /// Each vector's buffer (capacity `len` once allocated) and how many of its values
    /// are zeroed.
    slots: Vec<std::sync::Mutex<(Vec<f64>, usize)>>,
}

/// Values an idle thread zeroes between two looks at whether it is still idle (64 KiB).
const IDLE_CHUNK: usize = 8192;

impl ZeroedByIdle {
    /// `count` vectors of `len` values to come, nothing allocated yet: an idle thread
    /// allocates each where it starts zeroing it (a reservation made earlier would change
    /// where the stages before put their memory, and reuse less of it).
    pub fn new(count: usize, len: usize) -> Self {
        ZeroedByIdle {
            len,
            slots: (0..count)
                .map(|_| std::sync::Mutex::new((Vec::new(), 0)))
                .collect(),
        }
    }

    /// Zeroes the vectors in order, a chunk at a time, while `busy()` says that the
    /// stage's other parts are still running; skips a vector another thread is zeroing.
    pub fn work_while(&self, busy: &dyn Fn() -> bool) {
        for slot in &self.slots {
            let Ok(mut guard) = slot.try_lock() else {
                continue;
            };
            let (v, done) = &mut *guard;
            // A room the allocator refuses is left to `take`.
            if v.capacity() < self.len && v.try_reserve_exact(self.len).is_err() {
                return;
            }
            while *done < self.len {
                if !busy() {
                    return;
                }
                let end = (*done + IDLE_CHUNK).min(self.len);
                v.spare_capacity_mut()[*done..end]
                    .iter_mut()
                    .for_each(|e| _ = e.write(0.0));
                *done = end;
            }
        }
    }

    /// A zeroed vector of the length given at [`ZeroedByIdle::new`]: the next one made
    /// ahead, its remaining values zeroed here by every thread, else [`zeroed_now`].
    pub fn take(&mut self) -> Vec<f64> {
        if self.slots.is_empty() {
            return zeroed_now(self.len);
        }
        let slot = self.slots.remove(0);
        let (mut v, done) = slot.into_inner().unwrap_or_else(|e| e.into_inner());
        if v.capacity() < self.len {
            return zeroed_now(self.len);
        }
        write_zeros(&mut v.spare_capacity_mut()[done..self.len]);
        // SAFETY: the first `done` values were written by `work_while` (under the slot's
        // lock, which `into_inner` has released to us) and the rest just above.
        unsafe { v.set_len(self.len) };
        v
    }
}

/// A `Vec` of `n` copies of `value`, or `Error::TooLarge` when the allocator refuses.
pub fn try_filled<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v = try_with_capacity(n, what)?;
    v.resize(n, value);
    Ok(v)
}

/// [`try_filled`] for a buffer read across its rows (a transform's columns): its pages are
/// asked to be huge pages (Linux transparent huge pages, where enabled), so that a pass
/// down a column of a 4097-wide grid does not miss the TLB at every row.
pub fn try_filled_huge<T: Clone>(n: usize, value: T, what: &str) -> Result<Vec<T>> {
    let mut v: Vec<T> = try_with_capacity(n, what)?;
    advise_huge_pages(v.as_mut_ptr().cast(), n * std::mem::size_of::<T>());
    v.resize(n, value);
    Ok(v)
}

/// [`try_zeroed`] for a buffer written once, block by block, soon after it is allocated (a
/// sparse factor's values): when it spans 2 to [`HUGE_ADVICE_MAX`] huge pages and the kernel
/// has twice as many free ([`huge_pages_free`]), its fresh pages are asked to be huge pages,
/// so that a first touch faults one 2 MiB page instead of 512 small ones (docs/flow.md,
/// "The factor's values on huge pages"). Without that much free, no advice: a fault would
/// otherwise stall while the kernel compacts memory.
pub fn try_zeroed_huge<T: Zeroed>(n: usize, what: &str) -> Result<Vec<T>> {
    let mut v: Vec<T> = try_zeroed(n, what)?;
    let bytes = n * std::mem::size_of::<T>();
    let pages = bytes / HUGE_PAGE;
    if (2..=HUGE_ADVICE_MAX).contains(&pages)
        && huge_pages_free().is_some_and(|free| free >= 2 * pages as u64)
    {
        advise_huge_pages(v.as_mut_ptr().cast(), bytes);
    }
    Ok(v)
}

/// Most huge pages [`try_zeroed_huge`] asks for in one buffer. On a virtual machine whose
/// host backs the guest's memory when it is first written, an occasional fresh huge page
/// costs tens of milliseconds: a first flow at 513² (8 huge pages a side) was faster with
/// them in most runs, one at 1025² (45 a side) slower in most (docs/flow.md, "The
/// factor's values on huge pages").
const HUGE_ADVICE_MAX: usize = 32;

/// Bytes of a (transparent) huge page on x86-64 and most 64-bit Linux systems.
const HUGE_PAGE: usize = 2 << 20;

/// Free 2 MiB blocks of the system's memory, from `/proc/buddyinfo` (`None` where it cannot
/// be read).
fn huge_pages_free() -> Option<u64> {
    std::fs::read_to_string("/proc/buddyinfo")
        .ok()
        .map(|text| huge_pages_in(&text))
}

/// Free 2 MiB blocks in a `/proc/buddyinfo` text: per zone, the free blocks of order 0, 1,
/// … (4 KiB · 2^order); those of order 9 are 2 MiB, those of order `k > 9` hold `2^(k − 9)`.
fn huge_pages_in(text: &str) -> u64 {
    text.lines()
        .filter_map(|line| line.split_once("zone"))
        .flat_map(|(_, rest)| {
            rest.split_whitespace()
                .skip(1)
                .enumerate()
                .filter(|&(order, _)| order >= 9)
                .map(|(order, count)| count.parse::<u64>().unwrap_or(0) << (order - 9).min(32))
        })
        .sum()
}

/// Asks the kernel to back the 2 MiB-aligned part of `bytes` bytes at `ptr` by huge pages,
/// before they are first touched. Advice only: whatever the answer, nothing else changes.
#[cfg(target_os = "linux")]
fn advise_huge_pages(ptr: *mut u8, bytes: usize) {
    const HUGE: usize = HUGE_PAGE;
    // `MADV_HUGEPAGE` (asm-generic/mman-common.h).
    const MADV_HUGEPAGE: i32 = 14;
    extern "C" {
        fn madvise(addr: *mut std::ffi::c_void, len: usize, advice: i32) -> i32;
    }
    let start = (ptr as usize).next_multiple_of(HUGE);
    let end = (ptr as usize + bytes) / HUGE * HUGE;
    if end > start {
        // SAFETY: the range lies inside this process's own allocation; `madvise` with
        // `MADV_HUGEPAGE` only sets a flag on those pages and never changes their contents.
        unsafe {
            madvise(start as *mut std::ffi::c_void, end - start, MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge_pages(_ptr: *mut u8, _bytes: usize) {}

/// An empty `Vec` with room for exactly `n` values, or `Error::TooLarge`.
pub fn try_with_capacity<T>(n: usize, what: &str) -> Result<Vec<T>> {
    let bytes = bytes_of::<T>(n, what)?;
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| refused(bytes, what))?;
    Ok(v)
}

/// Grows `v` to hold at least `n` values in total, or `Error::TooLarge`.
pub fn try_reserve_total<T>(v: &mut Vec<T>, n: usize, what: &str) -> Result<()> {
    let extra = n.saturating_sub(v.len());
    let bytes = bytes_of::<T>(n, what)?;
    v.try_reserve_exact(extra).map_err(|_| refused(bytes, what))
}

/// The error for an allocation the system refused: `limit` 0 says no configured limit was
/// exceeded, the operating system itself had no room (see [`Error`]'s message).
pub fn refused(bytes: u64, what: &str) -> Error {
    Error::TooLarge {
        bytes,
        limit: 0,
        what: what.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Free huge pages counted from a `/proc/buddyinfo` text by hand: orders 9 and 10 of
    /// each zone (an order-10 block is two huge pages), lower orders not at all.
    #[test]
    fn free_huge_pages_are_counted_from_the_buddy_lists() {
        let text = "Node 0, zone      DMA      0      0      0      0      0      0      0      0      1      1      3 \n\
                    Node 0, zone    DMA32      1      1      4      2      5      4      3      3      4      2    752 \n\
                    Node 0, zone   Normal   9753   6838   4630   2996   2781   1784    885    307    145     85    370 \n";
        assert_eq!(
            huge_pages_in(text),
            (1 + 2 * 3) + (2 + 2 * 752) + (85 + 2 * 370)
        );
        assert_eq!(huge_pages_in(""), 0);
        assert_eq!(huge_pages_in("Node 0, zone Normal 5 4 3\n"), 0);
        // A buffer advised (or not: a machine without free huge pages, or one too large)
        // is still zeros.
        for n in [3 << 19, (HUGE_ADVICE_MAX + 3) << 18] {
            let v: Vec<f64> = try_zeroed_huge(n, "a test buffer").unwrap();
            assert_eq!(v.len(), n);
            assert!(v.iter().all(|&x| x == 0.0));
        }
    }

    #[test]
    fn zeroed_buffers_are_zero() {
        let v: Vec<f64> = try_zeroed(1000, "test").unwrap();
        assert_eq!(v.len(), 1000);
        assert!(v.iter().all(|&x| x == 0.0));
        let c: Vec<Complex64> = try_zeroed(10, "test").unwrap();
        assert!(c.iter().all(|z| z.re == 0.0 && z.im == 0.0));
        let e: Vec<f64> = try_zeroed(0, "test").unwrap();
        assert!(e.is_empty());
    }

    /// Vectors zeroed in part, wholly or not at all by an idle thread, and more taken than
    /// were made: every one taken is `len` zeros. The idle thread stops when told, within a
    /// chunk, and leaves a vector another thread holds.
    #[test]
    fn vectors_zeroed_by_idle_threads_are_zero_however_far_they_got() {
        let len = 3 * IDLE_CHUNK + 5;
        for budget in [0usize, 1, 2, 5, 100] {
            let mut z = ZeroedByIdle::new(3, len);
            let looks = std::sync::atomic::AtomicUsize::new(0);
            z.work_while(&|| looks.fetch_add(1, std::sync::atomic::Ordering::SeqCst) < budget);
            let zeroed: Vec<usize> = z.slots.iter().map(|s| s.lock().unwrap().1).collect();
            // One chunk per look: each vector is three whole chunks and a short one.
            let expected: usize = (0..budget.min(12))
                .map(|i| if i % 4 == 3 { 5 } else { IDLE_CHUNK })
                .sum();
            assert_eq!(zeroed.iter().sum::<usize>(), expected, "budget {budget}");
            for _ in 0..4 {
                let v = z.take();
                assert_eq!(v.len(), len);
                assert!(v.iter().all(|&x| x == 0.0));
            }
        }
        // A vector held elsewhere is skipped.
        let z = ZeroedByIdle::new(2, 10);
        let held = z.slots[0].lock().unwrap();
        z.work_while(&|| true);
        assert_eq!(held.1, 0);
        drop(held);
        assert_eq!(z.slots[1].lock().unwrap().1, 10);
    }

    #[test]
    fn vectors_made_ahead_are_zero_and_taken_by_length_once() {
        let mut ahead = ZeroedAhead::start(vec![5, 3, 5]);
        let (a, b, c, d) = (ahead.take(5), ahead.take(3), ahead.take(5), ahead.take(5));
        for (v, n) in [(&a, 5), (&b, 3), (&c, 5), (&d, 5)] {
            assert_eq!(v.len(), n);
            assert!(v.iter().all(|&x| x == 0.0));
        }
        // The fourth was made on demand; none is left.
        assert_eq!(ahead.left(), 0);
        let mut some = ZeroedAhead::start(vec![7, 2]);
        assert_eq!(some.take(2).len(), 2);
        assert_eq!(some.left(), 1);
        let mut none = ZeroedAhead::start(vec![0]);
        assert_eq!(none.left(), 0);
        assert_eq!(none.take(4), vec![0.0; 4]);
    }

    #[test]
    fn impossible_sizes_are_refused_not_aborted() {
        // Overflowing byte counts, and a representable one no system can provide (2 EiB).
        for n in [usize::MAX, 1 << 62, (1usize << 61) + 3, 1 << 58] {
            // `black_box`: an unused allocation may otherwise be elided by the optimiser,
            // which then reports success without asking the system.
            match std::hint::black_box(try_zeroed::<f64>(n, "a huge buffer")) {
                Err(Error::TooLarge { what, .. }) => assert!(what.contains("a huge buffer")),
                other => panic!("expected TooLarge, got {:?}", other.map(|v| v.len())),
            }
            assert!(matches!(
                try_filled(n, 0u32, "x"),
                Err(Error::TooLarge { .. })
            ));
        }
        assert!(checked_cells(1 << 40, 1 << 40, "grid").is_err());
        assert_eq!(checked_cells(3, 4, "grid").unwrap(), 12);
    }
}
