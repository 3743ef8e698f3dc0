//! Connected components of the free region and their percolation classes.
//!
//! The grid is row-major `ny × nx`; a cell is *free* when it is not in contact. Two free cells
//! belong to the same cluster when a chain of neighbouring free cells joins them, where the
//! neighbours of `(i, j)` are `(i ± 1, j)` and `(i, j ± 1)` (4-connectivity: fluid does not
//! pass through a corner) or in addition the four diagonal cells (8-connectivity). With
//! periodic wrap along an axis, the first and the last index along it are neighbours too.
//!
//! Labels are `1..=K` in raster order of each cluster's first cell (the first cluster met when
//! reading row 0 left to right, then row 1, …), `0` on cells that are not free. They do not
//! depend on the number of threads, nor on how the grid is split for them.
//!
//! # Algorithm
//!
//! The rows are split into horizontal strips of a fixed height that depends on the grid size
//! only, labelled in parallel (rayon), each on its own:
//!
//! - every row is packed into 64-cell bit masks; the runs of free cells start where
//!   `bits & !(bits << 1)` is set, and the run holding a cell is one popcount away;
//! - a union–find over the *runs* (not the cells) joins neighbouring runs of consecutive
//!   rows. The neighbouring pairs are exactly the runs of `above & below` (4-connectivity;
//!   8-connectivity adds the same with `above` shifted by one column either way), so they
//!   are found with bit operations, one per pair, with no per-cell branching;
//! - union by the smaller index (Rem's algorithm) keeps every parent index below its child's,
//!   so one pass in index order numbers the components in raster order.
//!
//! The strips are then joined along their seams (and the periodic wraps) by a second, small
//! union–find over the strip components, and every row of the output is written, cell by
//! cell without data-dependent branches (random masks make branches mispredict).
//!
//! Memory: nothing is allocated per row; besides the output the only per-cell buffer is one
//! bit per cell; the runs' components wait in the output array itself until it is written.
//! Work buffers are kept per thread between calls (up to `KEEP_BYTES`): on virtual machines a
//! fresh buffer's first-touch page faults cost a good part of the labelling time.
//!
//! Per-cluster sums (area, free volume) are accumulated per run, then per strip component,
//! then per cluster, always in raster order over a partition that does not depend on the
//! thread count, so they are bit-for-bit reproducible too. Each run's sum is the plain
//! sequential sum of its cells; with AVX2 four runs are summed at once, one per vector lane,
//! which keeps that order.
//!
//! # Percolation classes
//!
//! For flow along an axis, a cluster is *spanning* when it touches both the first and the
//! last index along that axis, *dead-end* when it touches some boundary of the grid but does
//! not span, and *trapped* when it touches no boundary. An axis with periodic wrap has no
//! boundary. `Either` spans along axis 0 or axis 1, `Both` along both. The free volume is the
//! sum of the three class volumes: `V = V_pg + V_dead + V_trapped`.

use std::cell::RefCell;
use std::sync::Mutex;

use rayon::prelude::*;

use crate::alloc;
use crate::error::{Error, Result};

mod classify;
mod simd;
mod union_find;

pub use classify::{class_of, classify, Classification};
use simd::*;
use union_find::*;

/// Touch flag: the cluster has a cell in row 0.
pub const TOUCH_FIRST_ROW: u8 = 1;
/// Touch flag: the cluster has a cell in row `ny − 1`.
pub const TOUCH_LAST_ROW: u8 = 2;
/// Touch flag: the cluster has a cell in column 0.
pub const TOUCH_FIRST_COL: u8 = 4;
/// Touch flag: the cluster has a cell in column `nx − 1`.
pub const TOUCH_LAST_COL: u8 = 8;

/// Class code of a cluster that spans the grid along the flow direction.
pub const SPANNING: u8 = 1;
/// Class code of a cluster that touches a boundary but does not span.
pub const DEAD_END: u8 = 2;
/// Class code of a cluster that touches no boundary.
pub const TRAPPED: u8 = 3;

/// Which cells are neighbours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Connectivity {
    /// Edge neighbours only.
    Four,
    /// Edge and corner neighbours.
    Eight,
}

impl Connectivity {
    /// `4` or `8`, the number of neighbours of an interior cell.
    pub fn from_neighbours(n: i64) -> Result<Self> {
        match n {
            4 => Ok(Connectivity::Four),
            8 => Ok(Connectivity::Eight),
            _ => Err(Error::invalid(
                "connectivity",
                format!("must be 4 (edge neighbours) or 8 (edges and corners), got {n}"),
            )),
        }
    }
}

/// Periodic wrap along each axis: with `axis0`, row `ny − 1` neighbours row 0; with `axis1`,
/// column `nx − 1` neighbours column 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Periodic {
    pub axis0: bool,
    pub axis1: bool,
}

/// Flow direction(s) used to call a cluster spanning.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Spans from row 0 to row `ny − 1`.
    Axis0,
    /// Spans from column 0 to column `nx − 1`.
    Axis1,
    /// Spans along axis 0 or along axis 1.
    Either,
    /// Spans along axis 0 and along axis 1.
    Both,
}

impl Flow {
    /// Parses `"0"`, `"1"`, `"either"` or `"both"`.
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "0" => Ok(Flow::Axis0),
            "1" => Ok(Flow::Axis1),
            "either" => Ok(Flow::Either),
            "both" => Ok(Flow::Both),
            _ => Err(Error::invalid(
                "flow",
                format!("must be \"0\", \"1\", \"either\" or \"both\", got {s:?}"),
            )),
        }
    }

    /// Rejects periodic wrap along a flow axis: a periodic surface wraps across the flow, and
    /// a fluid entering at the first index and leaving at the last one needs both to be
    /// boundaries.
    pub fn check_periodic(self, periodic: Periodic) -> Result<()> {
        let (along0, along1) = match self {
            Flow::Axis0 => (true, false),
            Flow::Axis1 => (false, true),
            Flow::Either | Flow::Both => (true, true),
        };
        let fix = match self {
            Flow::Axis0 => "wrap across the flow (axis 1) instead, or use no wrap",
            Flow::Axis1 => "wrap across the flow (axis 0) instead, or use no wrap",
            Flow::Either | Flow::Both => "every edge is an inlet or an outlet here: use no wrap",
        };
        if along0 && periodic.axis0 {
            return Err(Error::invalid(
                "periodic_axis0",
                format!("periodic wrap along a flow axis (0) leaves no inlet or outlet; {fix}"),
            ));
        }
        if along1 && periodic.axis1 {
            return Err(Error::invalid(
                "periodic_axis1",
                format!("periodic wrap along a flow axis (1) leaves no inlet or outlet; {fix}"),
            ));
        }
        Ok(())
    }
}

/// A source of the free-cell mask, read 64 cells at a time.
pub trait FreeCells: Sync {
    /// Number of cells.
    fn len(&self) -> usize;
    /// True when there are no cells.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Bit `k` is set iff cell `start + k` (row-major flat index) is free, for `k < len ≤ 64`;
    /// higher bits are zero.
    fn pack(&self, start: usize, len: usize) -> u64;
}

/// `true` = free.
pub struct FreeMask<'a>(pub &'a [bool]);
/// `true` = in contact; free is its complement.
pub struct ContactMask<'a>(pub &'a [bool]);
/// Free where the gap is positive (NaN is not positive; callers reject NaN gaps).
pub struct PositiveGap<'a>(pub &'a [f64]);

/// The one definition of an *open* cell, shared by the percolation classes and the flow: not
/// in contact and a positive gap (NaN is not positive). A free cell whose gap a solve left at
/// or below 0 conducts nothing, so it is closed.
#[inline(always)]
pub fn is_open(gap: f64, contact: bool) -> bool {
    !contact && gap > 0.0
}

/// The open cells ([`is_open`]) of a gap field and an optional contact mask (same length).
pub struct OpenCells<'a> {
    pub gap: &'a [f64],
    pub contact: Option<&'a [bool]>,
}

#[inline(always)]
fn low_mask(len: usize) -> u64 {
    if len >= 64 {
        u64::MAX
    } else {
        (1u64 << len) - 1
    }
}

/// Packs up to 64 bools into bits, eight at a time: a multiply gathers bit 0 of each byte of a
/// little-endian word into the top byte (the shifted copies never collide, so no carries).
#[inline(always)]
fn pack_bools(cells: &[bool]) -> u64 {
    let mut bits = 0u64;
    let mut shift = 0;
    let mut chunks = cells.chunks_exact(8);
    for c in &mut chunks {
        let word = u64::from_le_bytes([
            c[0] as u8, c[1] as u8, c[2] as u8, c[3] as u8, c[4] as u8, c[5] as u8, c[6] as u8,
            c[7] as u8,
        ]);
        bits |= (word.wrapping_mul(0x0102_0408_1020_4080) >> 56) << shift;
        shift += 8;
    }
    for (k, &c) in chunks.remainder().iter().enumerate() {
        bits |= (c as u64) << (shift + k);
    }
    bits
}

impl FreeCells for FreeMask<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline(always)]
    fn pack(&self, start: usize, len: usize) -> u64 {
        pack_bools(&self.0[start..start + len])
    }
}

impl FreeCells for ContactMask<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline(always)]
    fn pack(&self, start: usize, len: usize) -> u64 {
        !pack_bools(&self.0[start..start + len]) & low_mask(len)
    }
}

impl FreeCells for PositiveGap<'_> {
    fn len(&self) -> usize {
        self.0.len()
    }
    #[inline(always)]
    fn pack(&self, start: usize, len: usize) -> u64 {
        let mut bits = 0u64;
        for (k, &g) in self.0[start..start + len].iter().enumerate() {
            bits |= ((g > 0.0) as u64) << k;
        }
        bits
    }
}

impl FreeCells for OpenCells<'_> {
    fn len(&self) -> usize {
        self.gap.len()
    }
    #[inline(always)]
    fn pack(&self, start: usize, len: usize) -> u64 {
        let gaps = &self.gap[start..start + len];
        let mut bits = 0u64;
        match self.contact {
            Some(c) => {
                for (k, (&g, &c)) in gaps.iter().zip(&c[start..start + len]).enumerate() {
                    bits |= (is_open(g, c) as u64) << k;
                }
            }
            None => {
                for (k, &g) in gaps.iter().enumerate() {
                    bits |= (is_open(g, false) as u64) << k;
                }
            }
        }
        bits
    }
}

/// One strip component's sums.
#[derive(Clone, Copy)]
struct CompSum {
    area: u64,
    gap: f64,
    touch: u8,
}

/// The per-cluster sums of the clusters `first..` that start in one strip.
struct ClusterSums<'a> {
    area: &'a mut [u64],
    touch: &'a mut [u8],
    gap: &'a mut [f64],
}

impl ClusterSums<'_> {
    /// Adds a strip's component sums to their clusters (`map`), those of clusters that start in
    /// the strip (at `first..`) in place; returns the others.
    fn add_strip(&mut self, st: &CompSums, map: &[u32], first: usize) -> Vec<(u32, CompSum)> {
        let mut late = Vec::new();
        for ((&k, &[cells, gap]), &touch) in map.iter().zip(&st.sums).zip(&st.touch) {
            // `cells` is a whole number below 2⁵²: its bits above 2⁵² are the number itself
            // (cheaper than `as u64`, which has to saturate).
            const BIG: f64 = (1u64 << 52) as f64;
            let area = (cells + BIG).to_bits() - BIG.to_bits();
            match (k as usize).checked_sub(first) {
                Some(i) => {
                    self.area[i] += area;
                    self.touch[i] |= touch;
                    self.gap[i] += gap;
                }
                None => late.push((k, CompSum { area, gap, touch })),
            }
        }
        late
    }
}

/// Splits `v` into the consecutive pieces `v[bounds[i]..bounds[i + 1]]` (`bounds` is
/// non-decreasing, starts at 0 and ends at `v.len()`).
fn split_at<'a, T>(v: &'a mut [T], bounds: &[usize]) -> Vec<&'a mut [T]> {
    let mut rest = v;
    let mut pieces = Vec::with_capacity(bounds.len().saturating_sub(1));
    for w in bounds.windows(2) {
        let (piece, tail) = std::mem::take(&mut rest).split_at_mut(w[1] - w[0]);
        pieces.push(piece);
        rest = tail;
    }
    pieces
}

/// Strip height used for a grid: strips of at least ~32k cells so that a strip's work
/// outweighs its seam, and at most 128 strips. It depends on the grid only, never on the
/// thread count, so per-cluster sums are reproducible.
fn default_strip_rows(ny: usize, nx: usize) -> usize {
    const MIN_CELLS: usize = 1 << 15;
    const MAX_STRIPS: usize = 128;
    let by_cells = MIN_CELLS.div_ceil(nx.max(1));
    let by_count = ny.div_ceil(MAX_STRIPS);
    by_cells.max(by_count).clamp(1, ny.max(1))
}

/// Number of clusters and (with a gap field) per-cluster sums, before scaling by `dx²`.
#[derive(Default)]
struct Sums {
    n_clusters: usize,
    area: Vec<u64>,
    gap_sum: Vec<f64>,
    touch: Vec<u8>,
}

/// Checks that a `ny × nx` grid is supported (cell positions, run and component indices and
/// labels are `u32`); `name` is the argument reported in the error.
pub fn check_grid(name: &'static str, ny: usize, nx: usize) -> Result<usize> {
    match ny.checked_mul(nx) {
        Some(n) if n < u32::MAX as usize => Ok(n),
        _ => Err(Error::invalid(
            name,
            format!(
                "grids of more than {} cells are not supported, got shape ({ny}, {nx})",
                u32::MAX - 1
            ),
        )),
    }
}

fn check_shape(name: &'static str, len: usize, ny: usize, nx: usize) -> Result<()> {
    let n = check_grid(name, ny, nx)?;
    if len != n {
        return Err(Error::invalid(
            name,
            format!("has {len} cells, but the shape ({ny}, {nx}) needs {n}"),
        ));
    }
    Ok(())
}

/// Labels into `labels` (len `ny·nx`, any prior content) and returns the sums.
fn run<F: FreeCells>(
    free: &F,
    gap: Option<&[f64]>,
    setup: Setup,
    strip_rows: usize,
    labels: &mut [u32],
) -> Result<Sums> {
    let (ny, nx) = (setup.ny, setup.nx);
    if ny == 0 || nx == 0 {
        return Ok(Sums::default());
    }
    with_kept(&GRID, GridBuffers::bytes, |grid| {
        run_with(free, gap, setup, strip_rows, labels, grid)
    })
}

fn run_with<F: FreeCells>(
    free: &F,
    gap: Option<&[f64]>,
    setup: Setup,
    strip_rows: usize,
    labels: &mut [u32],
    grid: &mut GridBuffers,
) -> Result<Sums> {
    let (ny, nx) = (setup.ny, setup.nx);
    let strip_rows = strip_rows.clamp(1, ny);
    let nw = words(nx);
    let (chunk, bit_chunk) = (strip_rows * nx, strip_rows * nw);
    // One bit per cell: a few % of the labels' memory, so the final pass need not read the
    // source (which may be the gap field, 64 bits per cell) again.
    // Every word is written before it is read: stale content does not matter.
    let bits = &mut grid.bits;
    alloc::try_reserve_total(bits, ny * nw, "the free-cell bit mask")?;
    bits.resize(ny * nw, 0);

    let strips: Vec<Strip> = labels
        .par_chunks_mut(chunk)
        .zip(bits.par_chunks_mut(bit_chunk))
        .enumerate()
        .map(|(s, (out, b))| {
            with_kept(&SCRATCH, Scratch::bytes, |scratch| {
                label_strip_fast(free, gap, &setup, s * strip_rows, out, b, scratch)
            })
        })
        .collect::<Result<_>>()?;
    let n_strips = strips.len();

    // Strip components get global numbers in raster order: strip by strip.
    let mut comp_base = Vec::with_capacity(n_strips + 1);
    let mut total = 0usize;
    for st in &strips {
        comp_base.push(total as u32);
        total += st.n_comp as usize;
    }
    comp_base.push(total as u32);

    // Join the strips along their seams, and the last row to the first with axis-0 wrap.
    let gparent = &mut grid.parent;
    gparent.clear();
    alloc::try_reserve_total(gparent, total, "the union-find forest of the clusters")?;
    alloc::try_reserve_total(&mut grid.cluster, total, "the cluster numbers")?;
    alloc::try_reserve_total(&mut grid.rank, total, "the cluster ranks")?;
    gparent.extend(0..total as u32);
    let (mut above, mut below) = (RowBits::default(), RowBits::default());
    let region = |s: usize| &labels[s * chunk..((s + 1) * chunk).min(labels.len())];
    let mut join = |sa: usize, sb: usize| {
        let (a, b) = (&strips[sa], &strips[sb]);
        let last_row = (sa * strip_rows + a.rows() - 1) * nw;
        let first_row = sb * strip_rows * nw;
        above.load(&bits[last_row..last_row + nw]);
        below.load(&bits[first_row..first_row + nw]);
        let ca = a.row_comps(region(sa), a.rows() - 1);
        let cb = b.row_comps(region(sb), 0);
        let (ba, bb) = (comp_base[sa], comp_base[sb]);
        for_each_neighbour(&above, &below, &setup, |i, j| {
            union(gparent, ba + ca[i as usize], bb + cb[j as usize])
        });
    };
    for s in 1..n_strips {
        join(s - 1, s);
    }
    if setup.periodic.axis0 {
        join(n_strips - 1, 0);
    }
    grid.cluster.resize(total, 0);
    let cluster = &mut grid.cluster[..total];
    let n_clusters = number_components(gparent, &mut grid.rank, cluster) as usize;
    let cluster: &[u32] = cluster;

    let mut sums = Sums {
        n_clusters,
        ..Sums::default()
    };
    // With a gap field, a cluster's sums add its strip components in raster order, whatever
    // the thread count. Clusters are numbered in order of their first component, so those
    // starting in strip s are a contiguous range `first[s]..first[s + 1]`, summed by the
    // thread of strip s as it writes the strip's labels; components joining a cluster begun in
    // an earlier strip are added after, strip by strip, which keeps the raster order.
    let stats = gap.is_some();
    let first: Vec<usize> = (0..=n_strips)
        .map(|s| match comp_base[s] as usize {
            c if c < total => grid.rank[c] as usize,
            _ => n_clusters,
        })
        .collect();
    let mut pieces: Vec<Option<ClusterSums>> = (0..n_strips).map(|_| None).collect();
    if stats {
        // Zeroed in parallel: fresh memory is faulted in on first touch, a good part of the
        // cost on virtual machines.
        sums.area
            .par_extend(rayon::iter::repeat_n(0u64, n_clusters));
        sums.touch
            .par_extend(rayon::iter::repeat_n(0u8, n_clusters));
        sums.gap_sum
            .par_extend(rayon::iter::repeat_n(0.0f64, n_clusters));
        let area = split_at(&mut sums.area, &first);
        let touch = split_at(&mut sums.touch, &first);
        let gap_sum = split_at(&mut sums.gap_sum, &first);
        for (p, ((area, touch), gap)) in pieces
            .iter_mut()
            .zip(area.into_iter().zip(touch).zip(gap_sum))
        {
            *p = Some(ClusterSums { area, touch, gap });
        }
    }
    let late: Vec<Vec<(u32, CompSum)>> = labels
        .par_chunks_mut(chunk)
        .zip(bits.par_chunks(bit_chunk))
        .zip(pieces)
        .enumerate()
        .map_init(Vec::new, |lab, (s, ((out, b), piece))| {
            let map = &cluster[comp_base[s] as usize..comp_base[s + 1] as usize];
            finish_strip(&strips[s], out, b, nx, map, lab);
            match piece {
                Some(mut p) => p.add_strip(&strips[s].sums, map, first[s]),
                None => Vec::new(),
            }
        })
        .collect();
    for (k, v) in late.into_iter().flatten() {
        let k = k as usize;
        sums.area[k] += v.area;
        sums.touch[k] |= v.touch;
        sums.gap_sum[k] += v.gap;
    }
    if stats {
        CompSums::give_back(strips.into_iter().map(|st| st.sums));
    }
    Ok(sums)
}

fn setup(ny: usize, nx: usize, connectivity: Connectivity, periodic: Periodic) -> Setup {
    Setup {
        ny,
        nx,
        connectivity,
        periodic,
    }
}

/// Labels the free cells of a row-major `ny × nx` mask (`true` = free).
///
/// Returns the labels (`0` on non-free cells, `1..=K` in raster order of each cluster's first
/// cell) and the number of clusters `K`. Runs on the current rayon thread pool.
pub fn label(
    free: &[bool],
    ny: usize,
    nx: usize,
    connectivity: Connectivity,
    periodic: Periodic,
) -> Result<(Vec<u32>, usize)> {
    let mut labels = vec![0u32; free.len()];
    let n = label_into(&FreeMask(free), ny, nx, connectivity, periodic, &mut labels)?;
    Ok((labels, n))
}

/// [`label`] for any source of the free mask, into a caller's buffer of `ny·nx` cells (its
/// prior content is ignored); returns the number of clusters.
///
/// Let the caller own the (large) output so that it can come from an allocator that backs it
/// with huge pages: on some virtual machines, first-touch page faults of 4 KiB pages cost more
/// than the labelling itself.
pub fn label_into<F: FreeCells>(
    free: &F,
    ny: usize,
    nx: usize,
    connectivity: Connectivity,
    periodic: Periodic,
    labels: &mut [u32],
) -> Result<usize> {
    check_shape("mask", free.len(), ny, nx)?;
    check_shape("labels", labels.len(), ny, nx)?;
    let s = setup(ny, nx, connectivity, periodic);
    let sums = run(free, None, s, default_strip_rows(ny, nx), labels)?;
    Ok(sums.n_clusters)
}

/// Per-cluster sums of the free region. Cluster `k` (label `k`) is entry `k − 1` of every
/// per-cluster vector.
#[derive(Clone, Debug, PartialEq)]
pub struct Clusters {
    pub ny: usize,
    pub nx: usize,
    pub connectivity: Connectivity,
    pub periodic: Periodic,
    pub n_clusters: usize,
    /// Number of cells of each cluster.
    pub areas: Vec<u64>,
    /// `dx² Σ g` over the cells of each cluster (length³).
    pub volumes: Vec<f64>,
    /// `TOUCH_*` flags of each cluster.
    pub touches: Vec<u8>,
}

/// Labels the free cells given by `free` and sums, per cluster, the cells and the free volume
/// `dx² Σ g` of the gap field `gap` (row-major, same shape). The gap must be finite everywhere.
/// Returns the labels (as [`label`]) and the sums.
pub fn analyze<F: FreeCells>(
    free: &F,
    gap: &[f64],
    ny: usize,
    nx: usize,
    dx: f64,
    connectivity: Connectivity,
    periodic: Periodic,
) -> Result<(Vec<u32>, Clusters)> {
    let mut labels = vec![0u32; free.len()];
    let c = analyze_into(free, gap, ny, nx, dx, connectivity, periodic, &mut labels)?;
    Ok((labels, c))
}

/// [`analyze`] into a caller's label buffer (see [`label_into`]).
#[allow(clippy::too_many_arguments)]
pub fn analyze_into<F: FreeCells>(
    free: &F,
    gap: &[f64],
    ny: usize,
    nx: usize,
    dx: f64,
    connectivity: Connectivity,
    periodic: Periodic,
    labels: &mut [u32],
) -> Result<Clusters> {
    analyze_strips(
        free,
        gap,
        setup(ny, nx, connectivity, periodic),
        dx,
        default_strip_rows(ny, nx),
        labels,
    )
}

fn analyze_strips<F: FreeCells>(
    free: &F,
    gap: &[f64],
    setup: Setup,
    dx: f64,
    strip_rows: usize,
    labels: &mut [u32],
) -> Result<Clusters> {
    let (ny, nx) = (setup.ny, setup.nx);
    check_shape("mask", free.len(), ny, nx)?;
    check_shape("gap", gap.len(), ny, nx)?;
    check_shape("labels", labels.len(), ny, nx)?;
    if !(dx.is_finite() && dx > 0.0) {
        return Err(Error::invalid(
            "dx",
            format!("must be a positive finite grid spacing, got {dx}"),
        ));
    }
    let sums = run(free, Some(gap), setup, strip_rows, labels)?;
    let cell = dx * dx;
    let mut volumes = sums.gap_sum;
    for v in &mut volumes {
        *v *= cell;
    }
    Ok(Clusters {
        ny,
        nx,
        connectivity: setup.connectivity,
        periodic: setup.periodic,
        n_clusters: sums.n_clusters,
        areas: sums.area,
        volumes,
        touches: sums.touch,
    })
}

#[cfg(test)]
mod tests;
