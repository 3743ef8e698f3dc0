//! Union-find over the free runs of two adjacent rows: row bit masks, neighbour pairs under
//! 4- or 8-connectivity, the union with path halving and the numbering of components.

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
