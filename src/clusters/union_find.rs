//! Union-find over the free runs of two adjacent rows: row bit masks, neighbour pairs under
//! 4- or 8-connectivity, the union with path halving and the numbering of components; and
//! the strip pass built on them (rows labelled in strips, strips joined at their seams).

use super::*;

/// Number of 64-cell words per row.
pub(super) fn words(nx: usize) -> usize {
    nx.div_ceil(64)
}

/// One row as bit masks: free cells, run starts, and the number of runs begun before each
/// word, so that the run holding a cell is found with one popcount.
#[derive(Default)]
pub(super) struct RowBits {
    pub(super) bits: Vec<u64>,
    pub(super) starts: Vec<u64>,
    pub(super) before: Vec<u32>,
    pub(super) runs: u32,
}

impl RowBits {
    /// Loads a row's free bits (bits past the row's end must be zero).
    #[inline(always)]
    pub(super) fn load(&mut self, bits: &[u64]) {
        self.bits.clear();
        self.bits.extend_from_slice(bits);
        self.starts.clear();
        self.before.clear();
        let mut carry = 0u64;
        let mut n = 0u32;
        for &b in bits {
            // A run starts at a free cell whose left neighbour is not free.
            let s = b & !((b << 1) | carry);
            carry = b >> 63;
            self.before.push(n);
            self.starts.push(s);
            n += s.count_ones();
        }
        self.runs = n;
    }

    #[inline]
    pub(super) fn is_free(&self, x: usize) -> bool {
        (self.bits[x / 64] >> (x % 64)) & 1 != 0
    }

    /// Index, within the row, of the run holding the free cell `x`.
    #[inline(always)]
    fn run_at(&self, x: usize) -> u32 {
        let (w, b) = (x / 64, x % 64);
        // Starts at or left of bit b; `2 << 63` wraps to 0, giving the full mask.
        self.before[w] + (self.starts[w] & (2u64 << b).wrapping_sub(1)).count_ones() - 1
    }
}

/// Calls `f(i, j)` once for each pair of run `i` of row `a` and run `j` of row `b` (two
/// vertically adjacent rows) that are neighbours through a shared column (`SHIFT = 0`), or
/// diagonally with `a`'s cell one column left (`SHIFT = 1`) or right (`SHIFT = -1`) of `b`'s.
///
/// Where a (shifted) run of `a` overlaps a run of `b`, the common cells form one contiguous
/// stretch, and stretches of different pairs are separated by a blocked cell (runs of a row
/// are). So each pair is met exactly once, at the first cell of its stretch, and those cells
/// are the starts of the runs of `a & b` — found 64 at a time, with no per-run branching
/// except the loop over the pairs themselves.
#[inline(always)]
pub(super) fn for_each_pair<const SHIFT: i32>(
    a: &RowBits,
    b: &RowBits,
    mut f: impl FnMut(u32, u32),
) {
    let n = a.bits.len();
    let mut carry = 0u64;
    for w in 0..n {
        let aw = match SHIFT {
            0 => a.bits[w],
            1 => (a.bits[w] << 1) | if w > 0 { a.bits[w - 1] >> 63 } else { 0 },
            _ => (a.bits[w] >> 1) | if w + 1 < n { a.bits[w + 1] << 63 } else { 0 },
        };
        let o = aw & b.bits[w];
        let mut s = o & !((o << 1) | carry);
        carry = o >> 63;
        while s != 0 {
            let x = w * 64 + s.trailing_zeros() as usize;
            let xa = (x as isize - SHIFT as isize) as usize;
            f(a.run_at(xa), b.run_at(x));
            s &= s - 1;
        }
    }
}

/// Calls `f(i, j)` for every pair of neighbouring runs of the vertically adjacent rows `a`
/// (above) and `b` (below).
#[inline(always)]
pub(super) fn for_each_neighbour(
    a: &RowBits,
    b: &RowBits,
    setup: &Setup,
    mut f: impl FnMut(u32, u32),
) {
    for_each_pair::<0>(a, b, &mut f);
    if setup.connectivity == Connectivity::Eight {
        for_each_pair::<1>(a, b, &mut f);
        for_each_pair::<-1>(a, b, &mut f);
        if setup.periodic.axis1 {
            // Corner neighbours across the axis-1 wrap.
            let last = setup.nx - 1;
            if a.is_free(last) && b.is_free(0) {
                f(a.runs - 1, 0);
            }
            if a.is_free(0) && b.is_free(last) {
                f(0, b.runs - 1);
            }
        }
    }
}

/// Joins the sets of `x` and `y` in a forest where every parent index is at most its
/// child's, keeping it so: a set's root is its smallest index (its first element in raster
/// order).
///
/// Rem's algorithm with splicing: climb from both ends at once, always from the side whose
/// parent is larger, re-pointing it to the smaller parent on the way. It stops as soon as the
/// two paths meet, so the common case here — a fresh run joining its first neighbour above —
/// costs one step.
#[inline(always)]
pub(super) fn union(parent: &mut [u32], mut x: u32, mut y: u32) {
    loop {
        let (px, py) = (parent[x as usize], parent[y as usize]);
        if px == py {
            return;
        }
        if px > py {
            parent[x as usize] = py;
            if px == x {
                return;
            }
            x = px;
        } else {
            parent[y as usize] = px;
            if py == y {
                return;
            }
            y = py;
        }
    }
}

/// Numbers the components of a union–find forest whose parents precede their children:
/// `comp[i]` gets the component of entry `i`, components numbered `0..` in order of their
/// first element; returns the count. `parent` is flattened on the way; `rank` is scratch.
///
/// In index order, an entry's parent has already been pointed at its root, so one step
/// flattens the entry too; a component's number is the count of roots before its root. Written
/// without selects: a select here gets compiled to a branch that mispredicts on random masks.
pub(super) fn number_components(parent: &mut [u32], rank: &mut Vec<u32>, comp: &mut [u32]) -> u32 {
    rank.clear();
    rank.resize(parent.len(), 0);
    let mut n = 0u32;
    for i in 0..parent.len() {
        let root = parent[parent[i] as usize];
        parent[i] = root;
        rank[i] = n;
        n += (root as usize == i) as u32;
    }
    for (c, &p) in comp.iter_mut().zip(parent.iter()) {
        *c = rank[p as usize];
    }
    n
}

/// Makes `v` at least `n` long, at least doubling it when it grows.
#[inline(always)]
pub(super) fn grow<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
    if v.len() < n {
        grow_to(v, n);
    }
}

#[cold]
pub(super) fn grow_to<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
    let len = n.max(2 * v.len());
    v.resize(len, T::default());
}

/// Writes one row of labels. `lab` holds, for each stretch between run boundaries of the row,
/// its label: `lab[0] = 0` (before the first run), then `label, 0` for each run.
///
/// Indexing by the number of boundaries passed makes the loop free of data-dependent
/// branches (a select on the free bit gets compiled to a branch, which mispredicts on
/// random masks).
#[inline]
pub(super) fn write_row(row: &mut [u32], bits: &[u64], lab: &[u32]) {
    #[inline(always)]
    pub(super) fn word(cells: &mut [u32], t: u64, idx: &mut usize, lab: &[u32]) {
        let mut t = t;
        for o in cells.iter_mut() {
            *idx += (t & 1) as usize;
            t >>= 1;
            *o = lab[*idx];
        }
    }
    let (mut idx, mut carry) = (0usize, 0u64);
    let mut cells = row.chunks_exact_mut(64);
    let mut words = bits.iter();
    // Whole words first: a fixed trip count lets the compiler unroll.
    for (chunk, &b) in (&mut cells).zip(&mut words) {
        // Run boundaries: cells that differ from their left neighbour.
        word(chunk, b ^ ((b << 1) | carry), &mut idx, lab);
        carry = b >> 63;
    }
    if let Some(&b) = words.next() {
        word(
            cells.into_remainder(),
            b ^ ((b << 1) | carry),
            &mut idx,
            lab,
        );
    }
}

/// Per-thread buffers reused from strip to strip, so that nothing is allocated per row.
#[derive(Default)]
pub(super) struct Scratch {
    pub(super) prev: RowBits,
    pub(super) cur: RowBits,
    /// Union–find forest over the strip's runs, then each run's strip component.
    pub(super) parent: Vec<u32>,
    pub(super) rank: Vec<u32>,
    /// Per run of the strip (with sums only): cells (exact in an `f64`) and Σ gap. Grown,
    /// never shrunk: entries past the strip's runs are stale.
    pub(super) run_sums: Vec<[f64; 2]>,
    /// Positions of run starts and ends in a row (with sums only).
    pub(super) pos: Vec<u32>,
    /// Runs on the grid's edges and the edges they touch (with sums only).
    pub(super) edge: Vec<(u32, u8)>,
}

/// Buffers of the whole grid used while labelling it: the free bits, and the union–find over
/// the strip components with its scratch and result.
#[derive(Default)]
pub(super) struct GridBuffers {
    pub(super) bits: Vec<u64>,
    pub(super) parent: Vec<u32>,
    pub(super) rank: Vec<u32>,
    pub(super) cluster: Vec<u32>,
}

/// Kept buffers above this many bytes are dropped after use.
pub(super) const KEEP_BYTES: usize = 64 << 20;

thread_local! {
    // Kept between calls, per thread: fresh buffers of a few MB cost thousands of page
    // faults, which on virtual machines cost a good part of the labelling time.
    pub(super) static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
    pub(super) static GRID: RefCell<GridBuffers> = RefCell::new(GridBuffers::default());
}

impl Scratch {
    pub(super) fn bytes(&self) -> usize {
        4 * (self.parent.capacity() + self.rank.capacity() + self.pos.capacity())
            + 16 * self.run_sums.capacity()
    }
}

impl GridBuffers {
    pub(super) fn bytes(&self) -> usize {
        8 * self.bits.capacity()
            + 4 * (self.parent.capacity() + self.rank.capacity() + self.cluster.capacity())
    }
}

/// Runs `f` with this thread's kept buffers (or fresh ones if they are in use, which only a
/// re-entrant call could cause), then keeps them unless they grew too large.
pub(super) fn with_kept<T: Default, R>(
    key: &'static std::thread::LocalKey<RefCell<T>>,
    bytes: fn(&T) -> usize,
    f: impl FnOnce(&mut T) -> R,
) -> R {
    key.with(|cell| match cell.try_borrow_mut() {
        Ok(mut kept) => {
            let r = f(&mut kept);
            if bytes(&kept) > KEEP_BYTES {
                *kept = T::default();
            }
            r
        }
        Err(_) => f(&mut T::default()),
    })
}

/// What the seams, the final labelling and the per-cluster sums need of a labelled strip.
pub(super) struct Strip {
    pub(super) n_comp: u32,
    /// `row_runs[r]..row_runs[r + 1]` are the strip's runs in its row `r`.
    pub(super) row_runs: Vec<u32>,
    /// Per strip component (empty without a gap field).
    pub(super) sums: CompSums,
}

/// Per-component sums of a strip: cells (exact in an `f64`) and Σ gap, touch flags.
#[derive(Default)]
pub(super) struct CompSums {
    pub(super) sums: Vec<[f64; 2]>,
    pub(super) touch: Vec<u8>,
}

/// Strips' sums kept for later calls (as the thread-local buffers, to save page faults; a
/// strip's sums outlive its thread's work on it, so they are pooled instead).
pub(super) static COMP_SUMS: Mutex<Vec<CompSums>> = Mutex::new(Vec::new());

impl CompSums {
    pub(super) fn bytes(&self) -> usize {
        16 * self.sums.capacity() + self.touch.capacity()
    }

    /// Zeroed sums for `n` components, reusing pooled memory when there is some.
    pub(super) fn take(n: usize) -> Self {
        let mut s = lock(&COMP_SUMS).pop().unwrap_or_default();
        s.sums.clear();
        s.sums.resize(n, [0.0; 2]);
        s.touch.clear();
        s.touch.resize(n, 0);
        s
    }

    /// Returns sums to the pool, up to `KEEP_BYTES` in all.
    pub(super) fn give_back(all: impl Iterator<Item = CompSums>) {
        let mut pool = lock(&COMP_SUMS);
        let mut bytes: usize = pool.iter().map(CompSums::bytes).sum();
        for s in all {
            if bytes + s.bytes() <= KEEP_BYTES {
                bytes += s.bytes();
                pool.push(s);
            }
        }
    }
}

/// Locks a pool; a panic while it was held cannot have left it inconsistent.
pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Strip {
    pub(super) fn n_runs(&self) -> usize {
        self.row_runs.last().copied().unwrap_or(0) as usize
    }

    pub(super) fn rows(&self) -> usize {
        self.row_runs.len() - 1
    }

    /// Strip components of the runs of the strip's row `r`, read from the strip's part of the
    /// label array between labelling and finishing (see `label_strip`).
    pub(super) fn row_comps<'a>(&self, out: &'a [u32], r: usize) -> &'a [u32] {
        let tail = out.len() - self.n_runs();
        &out[tail + self.row_runs[r] as usize..tail + self.row_runs[r + 1] as usize]
    }
}

#[derive(Clone, Copy)]
pub(super) struct Setup {
    pub(super) ny: usize,
    pub(super) nx: usize,
    pub(super) connectivity: Connectivity,
    pub(super) periodic: Periodic,
}

/// Labels the rows `row0..` of one strip on their own.
///
/// `out` is the strip's part of the label array and `bits` of the free-bit array. On return
/// `bits` holds the free cells, and the *last* `R` cells of `out` hold the strip component of
/// each of the strip's `R` runs; the rest of `out` is left as it was. (Storing them there
/// rather than in a separate array saves allocating, and faulting in, a few bytes per cell;
/// `finish_strip` reads them back before it overwrites them.) With a gap field, also checks
/// that its rows are finite and sums cells, gap and edge contacts per strip component.
/// `AVX2`: the CPU has AVX2 (only [`label_strip_fast`] sets it).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn label_strip<F: FreeCells, const AVX2: bool>(
    free: &F,
    gap: Option<&[f64]>,
    setup: &Setup,
    row0: usize,
    out: &mut [u32],
    bits: &mut [u64],
    scratch: &mut Scratch,
) -> Result<Strip> {
    // Sums are taken only with a gap field.
    let stats = gap.is_some();
    let nx = setup.nx;
    let nw = words(nx);
    let rows = out.len() / nx;
    let Scratch {
        prev,
        cur,
        parent,
        rank,
        run_sums,
        pos,
        edge,
    } = scratch;
    parent.clear();
    edge.clear();
    let mut row_runs = Vec::with_capacity(rows + 1);
    row_runs.push(0u32);

    for r in 0..rows {
        let start = (row0 + r) * nx;
        let row_bits = &mut bits[r * nw..(r + 1) * nw];
        for (k, word) in row_bits.iter_mut().enumerate() {
            let c = 64 * k;
            *word = free.pack(start + c, (nx - c).min(64));
        }
        cur.load(row_bits);
        let base = parent.len() as u32;
        parent.extend(base..base + cur.runs);
        // Axis-1 wrap joins a run reaching the last column to one starting at column 0.
        if setup.periodic.axis1 && cur.runs >= 2 && cur.is_free(0) && cur.is_free(nx - 1) {
            union(parent, base, base + cur.runs - 1);
        }
        if r > 0 {
            let pbase = row_runs[r - 1];
            for_each_neighbour(prev, cur, setup, |i, j| union(parent, pbase + i, base + j));
        }
        row_runs.push(base + cur.runs);

        if stats {
            let done = parent.len() - cur.runs as usize;
            let gap = gap.unwrap_or(&[]);
            row_sums::<AVX2>(cur, gap, start, pos, done, run_sums);
            // Checked after the sums (which are of no use if it fails) rather than before: the
            // sums read the row from main memory with work to overlap, the check then from the
            // caches.
            let row = &gap[start..start + nx];
            if !all_finite(row) {
                let j = row.iter().position(|v| !v.is_finite()).unwrap_or(0);
                return Err(Error::invalid(
                    "gap",
                    format!(
                        "must be finite; found {} at row {}, column {j}",
                        row[j],
                        row0 + r
                    ),
                ));
            }
            // Only runs on the grid's edges touch it: at most two per row, besides the first
            // and the last row.
            if cur.runs > 0 {
                let (k0, k1) = (base, base + cur.runs);
                if row0 + r == 0 {
                    edge.extend((k0..k1).map(|k| (k, TOUCH_FIRST_ROW)));
                }
                if row0 + r + 1 == setup.ny {
                    edge.extend((k0..k1).map(|k| (k, TOUCH_LAST_ROW)));
                }
                if cur.is_free(0) {
                    edge.push((k0, TOUCH_FIRST_COL));
                }
                if cur.is_free(nx - 1) {
                    edge.push((k1 - 1, TOUCH_LAST_COL));
                }
            }
        }
        std::mem::swap(prev, cur);
    }

    let tail = out.len() - parent.len();
    let n_comp = number_components(parent, rank, &mut out[tail..]);
    let comp: &[u32] = &out[tail..];

    let mut sums = CompSums::default();
    if stats {
        sums = CompSums::take(n_comp as usize);
        for &(k, flag) in edge.iter() {
            sums.touch[comp[k as usize] as usize] |= flag;
        }
        add_runs(&mut sums.sums, comp, &run_sums[..comp.len()]);
    }
    Ok(Strip {
        n_comp,
        row_runs,
        sums,
    })
}

/// Adds each run's cells and Σ gap (`runs`) to its component's (`comp`), in run order.
///
/// Consecutive runs often belong to one component (neighbours in a row joined through the
/// rows around them), and then each sum would wait for the previous one's store to be read
/// back. So a run of the same component as the one before continues that run's sums in a
/// register, and loads zeros from a slot past the end instead of the sums in memory: with
/// `S` the component's sum so far and `v` the run's, `0 + (v + S)` or `S + (v + 0)`, either
/// is `S + v`. The choice is a mask on vectors of both sums: a select would be compiled to a
/// branch, which mispredicts.
#[inline(always)]
pub(super) fn add_runs(sums: &mut Vec<[f64; 2]>, comp: &[u32], runs: &[[f64; 2]]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::*;
        let zero = sums.len();
        sums.push([0.0; 2]);
        let all: &mut [[f64; 2]] = sums;
        let mut prev = u32::MAX;
        // SAFETY: SSE2 is part of x86-64; loads and stores are of whole, in-bounds entries.
        unsafe {
            let mut acc = _mm_setzero_pd();
            for (&c, r) in comp.iter().zip(runs) {
                let same = c == prev;
                let keep = _mm_castsi128_pd(_mm_set1_epi64x(-(same as i64)));
                let slot = if same { zero } else { c as usize };
                let base = _mm_loadu_pd(all[slot].as_ptr());
                let v = _mm_add_pd(_mm_loadu_pd(r.as_ptr()), base);
                acc = _mm_add_pd(_mm_and_pd(keep, acc), v);
                _mm_storeu_pd(all[c as usize].as_mut_ptr(), acc);
                prev = c;
            }
        }
        sums.truncate(zero);
    }
    #[cfg(not(target_arch = "x86_64"))]
    for (&c, r) in comp.iter().zip(runs) {
        let s = &mut sums[c as usize];
        s[0] += r[0];
        s[1] += r[1];
    }
}

/// Whether every value is finite. `v · 0` is `±0` for a finite `v` and NaN otherwise, and NaN
/// sticks in a sum; sixteen independent sums vectorise without reordering any of them.
#[inline(always)]
pub(super) fn all_finite(row: &[f64]) -> bool {
    let mut acc = [0.0f64; 16];
    let mut chunks = row.chunks_exact(16);
    for c in &mut chunks {
        for (a, &v) in acc.iter_mut().zip(c) {
            *a += v * 0.0;
        }
    }
    let tail = chunks.remainder().iter().fold(0.0, |a, &v| a + v * 0.0);
    acc.iter().fold(tail, |a, &x| a + x) == 0.0
}

/// [`label_strip`] compiled for AVX2 (with POPCNT and BMI) or else for POPCNT, when the CPU
/// has them. Finding the run that holds a cell is a popcount, and the x86-64 baseline the
/// wheel is built for lacks the instruction (its software fallback is about ten
/// instructions); the sums of the runs' gaps and the run boundaries use AVX2 vectors.
#[allow(clippy::too_many_arguments)]
pub(super) fn label_strip_fast<F: FreeCells>(
    free: &F,
    gap: Option<&[f64]>,
    setup: &Setup,
    row0: usize,
    out: &mut [u32],
    bits: &mut [u64],
    scratch: &mut Scratch,
) -> Result<Strip> {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(enable = "popcnt")]
        #[allow(clippy::too_many_arguments)]
        unsafe fn with_popcnt<F: FreeCells>(
            free: &F,
            gap: Option<&[f64]>,
            setup: &Setup,
            row0: usize,
            out: &mut [u32],
            bits: &mut [u64],
            scratch: &mut Scratch,
        ) -> Result<Strip> {
            label_strip::<F, false>(free, gap, setup, row0, out, bits, scratch)
        }
        #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
        #[allow(clippy::too_many_arguments)]
        unsafe fn with_avx2<F: FreeCells>(
            free: &F,
            gap: Option<&[f64]>,
            setup: &Setup,
            row0: usize,
            out: &mut [u32],
            bits: &mut [u64],
            scratch: &mut Scratch,
        ) -> Result<Strip> {
            label_strip::<F, true>(free, gap, setup, row0, out, bits, scratch)
        }
        if std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("popcnt")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
        {
            // SAFETY: the CPU has every feature `with_avx2` is compiled for, just checked.
            return unsafe { with_avx2(free, gap, setup, row0, out, bits, scratch) };
        }
        if std::arch::is_x86_feature_detected!("popcnt") {
            // SAFETY: a `target_feature` function may be called only on a CPU with the
            // feature, which was just checked.
            return unsafe { with_popcnt(free, gap, setup, row0, out, bits, scratch) };
        }
    }
    label_strip::<F, false>(free, gap, setup, row0, out, bits, scratch)
}

/// Writes the final labels of a strip. `cluster` maps the strip's components to clusters.
///
/// The runs' components sit in the last `R` cells of `out` (see `label_strip`). A row's are read
/// before the row is written, and writing rows `..=r` cannot reach the components of later
/// rows: those rows hold at least one cell per remaining run, so the cells after row `r` number
/// at least the remaining runs.
pub(super) fn finish_strip(
    st: &Strip,
    out: &mut [u32],
    bits: &[u64],
    nx: usize,
    cluster: &[u32],
    lab: &mut Vec<u32>,
) {
    let nw = words(nx);
    for r in 0..st.rows() {
        let comps = st.row_comps(out, r);
        let need = 2 * comps.len() + 1;
        // `lab` = [0, label, 0, label, 0, …]; the zeros are never overwritten.
        if lab.len() < need {
            lab.resize(need, 0);
        }
        for (pair, &c) in lab[1..need].chunks_exact_mut(2).zip(comps) {
            pair[0] = cluster[c as usize] + 1;
        }
        write_row(
            &mut out[r * nx..(r + 1) * nx],
            &bits[r * nw..(r + 1) * nw],
            &lab[..need],
        );
    }
}
