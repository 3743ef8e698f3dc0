//! The fill-reducing elimination order of the flow's unknowns for the sparse Cholesky
//! factor ([`super::direct`]) and the cancellation-free elimination ([`super::gth`]).
//!
//! On grids from 2^18 cells (513²), and from 2^16 cells (257²) when at least 60 % of the
//! cells carry unknowns, the order is a geometric nested dissection ([`nd_order`]): each
//! rectangle cut across its longer side by the row or column with the fewest unknowns
//! within an eighth of its length from the middle (the whole grid's: within a 64th of it
//! from the line that halves the unknowns, so that the two sides, factored at once, take
//! about the same time), the two sides ordered first, the cut last, down to rectangles of
//! 8 cells. Its top cuts become large dense supernodes, which
//! faer factors with dense kernels near the core's peak: on the mostly open gaps of a
//! contact sweep (84–100 % open) it needs 1.3–3.7× fewer flops than the minimum-degree
//! order below (2049², Δ = 0.05 h_s: 1.67e11 against 2.55e11; 1025², Δ = 0.5 h_s: 1.62e10
//! against 6.3e10) and orders in a few hundredths of the time; whole flows 20–45 % faster
//! (docs/flow.md). Below those sizes, and on gaps near the percolation threshold at 257²,
//! the minimum-degree order is faster.
//!
//! Otherwise the fill-reducing order is approximate minimum degree (faer's AMD), over 2 × 2 blocks of
//! cells ([`BLOCK`]) on pieces of up to a million cells (except 20,000 to 100,000), on
//! pieces of the grid:
//! the grid is cut in two by its middle row (or, without wrap and wider than tall, its
//! middle column), each half cut again ([`SPLIT_DEPTH`] times, pieces of at least
//! [`SPLIT_MIN`] cells); the pieces are ordered independently, in parallel, and the
//! separators come last. A separator couples only the two pieces it divides, so the order
//! does not depend on the thread count. The minimum-degree step is the costliest part of the
//! analysis on large grids; this puts every core on it for a little more fill.
//!
//! A full nested dissection by grid rows and columns (pieces cut down to 64–16,384 cells,
//! a wrapped grid first opened by its last column) orders in a fifth to a half of the
//! time, but these gaps are not full grids: the minimum-degree order follows their
//! channels and has half the fill (13.5 against 26–38 entries per unknown at 513², 24
//! against 29–32 at 1025²), which the solves pay for (docs/flow.md).
//!

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::SymbolicSparseColMatRef;

use super::assemble::Stencil;

/// Times the grid is halved for the ordering (up to `2^SPLIT_DEPTH` pieces).
const SPLIT_DEPTH: usize = 1;

/// Pieces with fewer cells than this are not cut further.
const SPLIT_MIN: usize = 1 << 16;

/// Side of the square blocks of cells the minimum-degree order is computed on, for pieces of
/// at most [`BLOCK_MAX_CELLS`] cells and pieces of [`BLOCK_FROM_CELLS`] to
/// [`BLOCK_UPTO_CELLS`] cells (cell by cell otherwise; a grid below `2 SPLIT_MIN` cells is
/// one piece). faer's supernodal factorisation
/// spends its time per supernode more than per flop, and the minimum-degree step costs
/// about in proportion to the nodes it orders: the order of 2 × 2 blocks, whose factor has
/// 1.8–2.6× the entries of the cell-by-cell order, takes a quarter of the time to compute
/// and its factor is no slower up to about a million cells a piece. On the contact gaps of
/// the flow benchmarks (one thread) a whole flow takes 20–30 % less time at 97² to 129²,
/// 36 % less at 513² and 18–38 % less at 1025² (two gaps); at 257² (one piece of 66,049
/// cells) it took 15 % more, and at 2049² (pieces of 2.1 million cells: 1.9–2.2× the
/// entries, the numeric factor 1.2–2.7× slower) 23 % more (docs/flow.md).
const BLOCK: usize = 2;

/// Largest small piece (cells of its rectangle) ordered by [`BLOCK`]-sized blocks.
const BLOCK_MAX_CELLS: usize = 20_000;

/// Smallest large piece ordered by [`BLOCK`]-sized blocks (above the 66,049 cells of a
/// whole 257² grid, below the halves of 513², 131,328 cells).
const BLOCK_FROM_CELLS: usize = 100_000;

/// Largest large piece ordered by [`BLOCK`]-sized blocks.
const BLOCK_UPTO_CELLS: usize = 1 << 20;

/// Elimination order (new position → unknown) of the unknowns `index` (grid cell → unknown,
/// `usize::MAX` for none) for the factor: the nested dissection ([`nd_order`]) on grids of at
/// least [`ND_ALWAYS_CELLS`] cells, and of at least [`ND_FROM_CELLS`] cells when at least
/// [`ND_OPEN_PERCENT`] % of them carry unknowns; the minimum-degree order on pieces otherwise
/// (module docs). With the nested dissection, also the sizes `(a, b)` of the two sides of
/// its top cut: the order is then side `a`, side `b`, and the separator last (the top cut,
/// and on a wrapped grid the column that opened it), no unknown of one side next to one of
/// the other (the halves of [`super::halves`]).
pub(super) fn ordering(
    st: &Stencil,
    index: &[usize],
    m: usize,
) -> (Vec<usize>, Option<(usize, usize)>) {
    let cells = st.ny * st.nx;
    if cells >= ND_ALWAYS_CELLS || (cells >= ND_FROM_CELLS && 100 * m >= ND_OPEN_PERCENT * cells) {
        nd_order(st, index, m)
    } else {
        (order_pieces(st, index, m, true), None)
    }
}

/// Grids of at least this many cells are ordered by nested dissection (512² cells: 513²
/// and up, where it was as fast or faster on every gap measured, open or at the threshold).
const ND_ALWAYS_CELLS: usize = 1 << 18;

/// Grids of at least this many cells (256²) are ordered by nested dissection when at least
/// [`ND_OPEN_PERCENT`] % of their cells carry unknowns.
const ND_FROM_CELLS: usize = 1 << 16;

/// See [`ND_FROM_CELLS`].
const ND_OPEN_PERCENT: usize = 60;

/// Rectangles of at most this many cells are not cut further by the nested dissection.
const ND_LEAF: usize = 8;

/// Rectangles of at least this many cells are cut by the row (column) with the fewest
/// unknowns within [`ND_REACH`]`⁻¹` of their height (width) from the middle.
const ND_SEARCH_CELLS: usize = 4096;

/// See [`ND_SEARCH_CELLS`].
const ND_REACH: usize = 8;

/// The top cut's search reaches this fraction of the side from the line halving the
/// unknowns ([`nd_region`]).
const ND_BALANCED_REACH: usize = 64;

/// Geometric nested dissection of the whole grid ([`nd_region`]); a wrapped grid is first
/// opened by its last column, which comes last. With the sizes of the two sides of the top
/// cut (none when the grid is not cut).
pub(super) fn nd_order(
    st: &Stencil,
    index: &[usize],
    m: usize,
) -> (Vec<usize>, Option<(usize, usize)>) {
    let mut out = Vec::with_capacity(m);
    let (ny, nx) = (st.ny, st.nx);
    let top = if st.periodic && nx > 2 {
        let top = nd_region(st, index, (0, ny), (0, nx - 1), true, &mut out);
        out.extend(
            (0..ny)
                .map(|i| index[i * nx + nx - 1])
                .filter(|&q| q != usize::MAX),
        );
        top
    } else {
        nd_region(st, index, (0, ny), (0, nx), true, &mut out)
    };
    (out, top)
}

/// Nested dissection of one rectangle: cut across its longer side by a row or column near
/// the middle ([`ND_SEARCH_CELLS`]), each side ordered the same way (in parallel when
/// large; the order does not depend on the thread count), the cut last; a rectangle of at
/// most [`ND_LEAF`] cells, or narrower than 3 both ways, in row-major order. Returns the
/// unknowns of the two sides when it was cut. With `balanced` (the top cut), the search is
/// centred on the line that halves the rectangle's unknowns rather than on its middle:
/// the two sides are then factored at once ([`super::halves`]), and a side with twice the
/// other's unknowns would keep one core waiting (the 2049² contact gap's sides had
/// 743,626 and 1,583,370 unknowns about the middle row).
fn nd_region(
    st: &Stencil,
    index: &[usize],
    r: (usize, usize),
    c: (usize, usize),
    balanced: bool,
    out: &mut Vec<usize>,
) -> Option<(usize, usize)> {
    let (h, w) = (r.1 - r.0, c.1 - c.0);
    if h == 0 || w == 0 {
        return None;
    }
    let nx = st.nx;
    if h * w <= ND_LEAF || (h < 3 && w < 3) {
        for i in r.0..r.1 {
            out.extend(
                (c.0..c.1)
                    .map(|j| index[i * nx + j])
                    .filter(|&q| q != usize::MAX),
            );
        }
        return None;
    }
    // The cut at `lo + 1 .. lo + long − 1` with the fewest unknowns within `long / ND_REACH`
    // of the middle (balanced: of the line halving the unknowns), the nearest to it on ties.
    let best = |lo: usize, long: usize, count: &dyn Fn(usize) -> usize| -> usize {
        let mid = if balanced {
            let counts: Vec<usize> = (lo..lo + long).map(count).collect();
            let half = counts.iter().sum::<usize>() / 2;
            let mut seen = 0;
            let at = counts
                .iter()
                .position(|&n| {
                    seen += n;
                    seen > half
                })
                .unwrap_or(long / 2);
            lo + at.clamp(1, long - 2)
        } else {
            lo + long / 2
        };
        if h * w < ND_SEARCH_CELLS {
            return mid;
        }
        let mut pick = (count(mid), 0usize, mid);
        // Balanced, a narrower search: each line moved shifts a line's unknowns from one
        // side to the other.
        let reach = if balanced {
            long / ND_BALANCED_REACH
        } else {
            long / ND_REACH
        };
        for d in 1..=reach {
            for cand in [mid.saturating_sub(d), mid + d] {
                if cand > lo && cand + 1 < lo + long {
                    pick = pick.min((count(cand), d, cand));
                }
            }
        }
        pick.2
    };
    let active = |i: usize, j: usize| index[i * nx + j] != usize::MAX;
    let ((ra, ca), (rb, cb), sep): (_, _, Vec<usize>) = if h >= w {
        let mid = best(r.0, h, &|i| (c.0..c.1).filter(|&j| active(i, j)).count());
        (
            ((r.0, mid), c),
            ((mid + 1, r.1), c),
            (c.0..c.1).map(|j| index[mid * nx + j]).collect(),
        )
    } else {
        let mid = best(c.0, w, &|j| (r.0..r.1).filter(|&i| active(i, j)).count());
        (
            (r, (c.0, mid)),
            (r, (mid + 1, c.1)),
            (r.0..r.1).map(|i| index[i * nx + mid]).collect(),
        )
    };
    let start = out.len();
    let na = if h * w >= 1 << 16 {
        let (mut a, mut b) = (Vec::new(), Vec::new());
        rayon::join(
            || nd_region(st, index, ra, ca, false, &mut a),
            || nd_region(st, index, rb, cb, false, &mut b),
        );
        let na = a.len();
        out.extend(a);
        out.extend(b);
        na
    } else {
        nd_region(st, index, ra, ca, false, out);
        let na = out.len() - start;
        nd_region(st, index, rb, cb, false, out);
        na
    };
    let nb = out.len() - start - na;
    out.extend(sep.into_iter().filter(|&q| q != usize::MAX));
    Some((na, nb))
}

/// [`ordering`] with blocks on the small pieces only (at most [`BLOCK_MAX_CELLS`] cells), for
/// the cancellation-free elimination ([`super::gth`]), whose cost grows with the fill more
/// than the supernodal factor's.
pub(super) fn elimination_ordering(st: &Stencil, index: &[usize], m: usize) -> Vec<usize> {
    order_pieces(st, index, m, false)
}

/// The whole grid's order; `large_blocks` as in [`region_order`].
fn order_pieces(st: &Stencil, index: &[usize], m: usize, large_blocks: bool) -> Vec<usize> {
    let mut out = Vec::with_capacity(m);
    let whole = ((0, st.ny), (0, st.nx));
    region_order(
        st,
        index,
        whole.0,
        whole.1,
        SPLIT_DEPTH,
        large_blocks,
        &mut out,
    );
    out
}

fn region_order(
    st: &Stencil,
    index: &[usize],
    r: (usize, usize),
    c: (usize, usize),
    depth: usize,
    large_blocks: bool,
    out: &mut Vec<usize>,
) {
    let (h, w) = (r.1 - r.0, c.1 - c.0);
    if h == 0 || w == 0 {
        return;
    }
    // With wrap, a column does not cut the cylinder: rows only.
    let by_rows = (st.periodic && c == (0, st.nx)) || h >= w;
    let long = if by_rows { h } else { w };
    if depth == 0 || h * w < 2 * SPLIT_MIN || long < 3 {
        let cells = h * w;
        let blocks = cells <= BLOCK_MAX_CELLS
            || (large_blocks && (BLOCK_FROM_CELLS..=BLOCK_UPTO_CELLS).contains(&cells));
        amd_region(st, index, r, c, if blocks { BLOCK } else { 1 }, out);
        return;
    }
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let nx = st.nx;
    let sep: Vec<usize> = if by_rows {
        let mid = r.0 + h / 2;
        rayon::join(
            || region_order(st, index, (r.0, mid), c, depth - 1, large_blocks, &mut a),
            || {
                region_order(
                    st,
                    index,
                    (mid + 1, r.1),
                    c,
                    depth - 1,
                    large_blocks,
                    &mut b,
                )
            },
        );
        (c.0..c.1).map(|j| index[mid * nx + j]).collect()
    } else {
        let mid = c.0 + w / 2;
        rayon::join(
            || region_order(st, index, r, (c.0, mid), depth - 1, large_blocks, &mut a),
            || {
                region_order(
                    st,
                    index,
                    r,
                    (mid + 1, c.1),
                    depth - 1,
                    large_blocks,
                    &mut b,
                )
            },
        );
        (r.0..r.1).map(|i| index[i * nx + mid]).collect()
    };
    out.extend(a);
    out.extend(b);
    out.extend(sep.into_iter().filter(|&q| q != usize::MAX));
}

/// Approximate-minimum-degree order of the unknowns in one rectangle of the grid (faces to
/// cells outside it do not count: those cells are separators, eliminated later), computed on
/// square blocks of cells ([`BLOCK`] on the rectangles listed there, the large ones only with
/// `large_blocks`; single cells otherwise): two blocks
/// are neighbours when a face with positive conductance joins them, and each block's
/// unknowns follow one another, row-major, at the block's place in the order.
fn amd_region(
    st: &Stencil,
    index: &[usize],
    r: (usize, usize),
    c: (usize, usize),
    blk: usize,
    out: &mut Vec<usize>,
) {
    let nx = st.nx;
    let (h, w) = (r.1 - r.0, c.1 - c.0);
    let wrap = st.periodic && c == (0, nx) && nx > 2;
    let (bh, bw) = (h.div_ceil(blk), w.div_ceil(blk));
    let block_of = |i: usize, j: usize| ((i - r.0) / blk) * bw + (j - c.0) / blk;
    // Blocks holding unknowns, numbered in raster order.
    let mut occupied = vec![false; bh * bw];
    for i in r.0..r.1 {
        for j in c.0..c.1 {
            if index[i * nx + j] != usize::MAX {
                occupied[block_of(i, j)] = true;
            }
        }
    }
    let mut number = vec![usize::MAX; bh * bw];
    let mut blocks = Vec::new();
    for (b, _) in occupied.iter().enumerate().filter(|(_, &o)| o) {
        number[b] = blocks.len();
        blocks.push(b);
    }
    let n = blocks.len();
    if n == 0 {
        return;
    }
    // Block edges (lower, upper) from the faces inside the rectangle, and the wrap faces.
    let mut edges = Vec::new();
    for i in r.0..r.1 {
        for j in c.0..c.1 {
            let k = i * nx + j;
            if index[k] == usize::MAX {
                continue;
            }
            let here = number[block_of(i, j)];
            let mut join = |i2: usize, j2: usize| {
                if index[i2 * nx + j2] != usize::MAX {
                    let there = number[block_of(i2, j2)];
                    if there != here {
                        edges.push((here.min(there), here.max(there)));
                    }
                }
            };
            if j + 1 < c.1 && st.e[k] > 0.0 {
                join(i, j + 1);
            }
            if i + 1 < r.1 && st.s[k] > 0.0 {
                join(i + 1, j);
            }
            if wrap && j == nx - 1 && st.e[k] > 0.0 {
                join(i, 0);
            }
        }
    }
    edges.sort_unstable_by_key(|&(lo, hi)| (hi, lo));
    edges.dedup();
    // Upper pattern (row < column) by columns.
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::with_capacity(edges.len());
    col_ptr.push(0usize);
    let mut e = 0;
    for q in 0..n {
        while e < edges.len() && edges[e].1 == q {
            row_idx.push(edges[e].0);
            e += 1;
        }
        col_ptr.push(row_idx.len());
    }
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
    let mut perm = vec![0usize; n];
    let mut perm_inv = vec![0usize; n];
    let req = faer::sparse::linalg::amd::order_scratch::<usize>(n, row_idx.len());
    let ordered = MemBuffer::try_new(req).ok().and_then(|mut buf| {
        faer::sparse::linalg::amd::order(
            &mut perm,
            &mut perm_inv,
            pattern,
            Default::default(),
            MemStack::new(&mut buf),
        )
        .ok()
    });
    if ordered.is_none() {
        // Block order: more fill, never a wrong answer.
        perm.iter_mut().enumerate().for_each(|(q, p)| *p = q);
    }
    for &q in &perm {
        let b = blocks[q];
        let (i0, j0) = (r.0 + (b / bw) * blk, c.0 + (b % bw) * blk);
        for i in i0..(i0 + blk).min(r.1) {
            for j in j0..(j0 + blk).min(c.1) {
                let u = index[i * nx + j];
                if u != usize::MAX {
                    out.push(u);
                }
            }
        }
    }
}
