//! The dead ends of the spanning clusters: cells through which no flow can pass, found as
//! the blocks (biconnected components) off the inlet-to-outlet block.
//!
//! The graph: the spanning cells joined through their open faces, the inlet reservoir `I`
//! joined to the spanning cells of the first row, the outlet `O` to those of the last, and
//! one more edge `I–O`. A cell lies on a simple path from inlet to outlet exactly when it
//! is in the block of the edge `I–O` (the backbone). Every other cell hangs off the
//! backbone through one vertex, its anchor (an articulation point): the region behind it
//! meets the rest of the flow only there, so in the steady state its fluid is at rest at
//! the anchor's pressure, and its faces carry no flux. Solving on the backbone alone gives
//! the same pressures and fluxes there (eliminating a dead end adds nothing to its anchor's
//! equation: the region's rows sum to zero) and these pressures exactly, where a factor of
//! the whole system would fix a pocket's pressure through its neck alone, whose `g³` may be
//! below the rounding of the pocket's own faces (docs/flow.md, "Dead ends").
//!
//! One depth-first search with low points (Hopcroft–Tarjan), iterative, in `O(cells)`.

use rayon::prelude::*;

/// A cell that is not a dead end (on the backbone, or not spanning).
const NONE: u32 = u32::MAX;
/// A dead end hanging off the inlet reservoir (pressure `Δp`).
pub const INLET: u32 = u32::MAX - 1;
/// A dead end hanging off the outlet reservoir (pressure 0).
pub const OUTLET: u32 = u32::MAX - 2;

/// Largest grid (cells) [`anchors`] takes: cell indices below the three markers.
pub const MAX_CELLS: usize = (u32::MAX - 3) as usize;

/// The dead-end cells with their anchors, `(cell, anchor)` by increasing cell (row-major
/// indices): the backbone cell, [`INLET`] or [`OUTLET`] whose pressure the dead end takes.
/// `spanning`: the cells of the spanning clusters on the row-major `ny × nx` grid, flow
/// along axis 0 (inlet before row 0, outlet after row `ny − 1`), wrapped across axis 1 when
/// `periodic`.
pub fn anchors(spanning: &[bool], ny: usize, nx: usize, periodic: bool) -> Vec<(u32, u32)> {
    let n = ny * nx;
    assert!(n <= MAX_CELLS && spanning.len() == n);
    if !spanning.par_iter().any(|&s| s) {
        return Vec::new();
    }
    let edges = edge_masks(spanning, ny, nx, periodic);
    let (mut visit, preorder) = search(&edges, spanning, ny, nx);
    // The backbone is the block of the tree edge `I–O` (the inlet's first child is the
    // outlet). A child `c` of `p` shares `p`'s block iff `low(c) < disc(p)`. Each cell's
    // anchor, [`NONE`] on the backbone, is written over its low point once that is read (in
    // preorder, a parent before its children).
    let (inlet, outlet) = (n, n + 1);
    visit[inlet].low = NONE;
    visit[outlet].low = NONE;
    let mut dead = Vec::new();
    for &(c, p) in &preorder {
        let (c, p) = (c as usize, p as usize);
        let a = if p < n && visit[p].low != NONE {
            visit[p].low
        } else if visit[c].low >= visit[p].disc {
            // `visit[c].low` still holds `low(c)`: the edge `p–c` starts a block of its own.
            match p {
                p if p == inlet => INLET,
                p if p == outlet => OUTLET,
                p => p as u32,
            }
        } else {
            NONE
        };
        visit[c].low = a;
        if a != NONE {
            dead.push((c as u32, a));
        }
    }
    dead.par_sort_unstable();
    dead
}

/// Edge bits of a cell in [`edge_masks`]: to the cell above (the inlet on row 0), below (the
/// outlet on the last row), left and right.
const UP: u8 = 1;
const DOWN: u8 = 2;
const LEFT: u8 = 4;
const RIGHT: u8 = 8;
/// The left (right) edge wraps to the row's other end.
const LEFT_WRAPS: u8 = 16;
const RIGHT_WRAPS: u8 = 32;

/// Each spanning cell's edges in the graph ([`UP`] … [`RIGHT`], with [`LEFT_WRAPS`] and
/// [`RIGHT_WRAPS`] on the first and last columns of a wrapped grid); 0 off the spanning cells.
fn edge_masks(spanning: &[bool], ny: usize, nx: usize, periodic: bool) -> Vec<u8> {
    let n = ny * nx;
    let wraps = periodic && nx > 1;
    (0..n)
        .into_par_iter()
        .map(|u| {
            if !spanning[u] {
                return 0;
            }
            let j = u % nx;
            let mut m = 0;
            if u < nx || spanning[u - nx] {
                m |= UP;
            }
            if u + nx >= n || spanning[u + nx] {
                m |= DOWN;
            }
            if j > 0 {
                m |= if spanning[u - 1] { LEFT } else { 0 };
            } else if wraps {
                m |= LEFT_WRAPS | if spanning[u + nx - 1] { LEFT } else { 0 };
            }
            if j + 1 < nx {
                m |= if spanning[u + 1] { RIGHT } else { 0 };
            } else if wraps {
                m |= RIGHT_WRAPS | if spanning[u + 1 - nx] { RIGHT } else { 0 };
            }
            m
        })
        .collect()
}

/// A vertex's discovery time and low point side by side: the search reads and writes both
/// where it discovers a vertex, at scattered places (three separate arrays, parents
/// included, took a cache miss for each).
#[derive(Clone, Copy)]
struct Visit {
    disc: u32,
    low: u32,
}

/// The depth-first search with low points from the inlet `I = n` (first to the outlet
/// `O = n + 1` along the edge `I–O`): each vertex's discovery time and low point, and the
/// cells in preorder with their parents.
fn search(edges: &[u8], spanning: &[bool], ny: usize, nx: usize) -> (Vec<Visit>, Vec<(u32, u32)>) {
    let n = ny * nx;
    let (inlet, outlet) = (n, n + 1);
    const UNSEEN: u32 = u32::MAX;
    let mut visit = vec![
        Visit {
            disc: UNSEEN,
            low: 0
        };
        n + 2
    ];
    let mut preorder: Vec<(u32, u32)> = Vec::new();
    // Each reservoir's spanning cells, and how many of them it has tried.
    let rows: [Vec<u32>; 2] = [0, ny - 1].map(|i| {
        (i * nx..(i + 1) * nx)
            .filter(|&k| spanning[k])
            .map(|k| k as u32)
            .collect()
    });
    let mut tried = [0usize; 2];
    // (vertex, its edges not yet tried, with the wrap bits): the path from the inlet.
    let mut stack: Vec<(u32, u8)> = Vec::new();
    visit[inlet] = Visit { disc: 0, low: 0 };
    visit[outlet] = Visit { disc: 1, low: 1 };
    let mut time = 2u32;
    stack.push((inlet as u32, 0));
    stack.push((outlet as u32, 0));
    while let Some(&mut (u, ref mut left)) = stack.last_mut() {
        let u = u as usize;
        // The next neighbour and the edge bit by which it sees `u` (its parent edge if new).
        let next = if u >= n {
            let r = u - n;
            let row = &rows[r];
            if tried[r] < row.len() {
                tried[r] += 1;
                Some((row[tried[r] - 1] as usize, if r == 0 { UP } else { DOWN }))
            } else {
                None
            }
        } else if *left & 15 == 0 {
            None
        } else {
            let bit = *left & left.wrapping_neg();
            *left &= !bit;
            Some(match bit {
                UP => (if u < nx { inlet } else { u - nx }, DOWN),
                DOWN => (if u + nx >= n { outlet } else { u + nx }, UP),
                LEFT => (
                    if *left & LEFT_WRAPS != 0 {
                        u + nx - 1
                    } else {
                        u - 1
                    },
                    RIGHT,
                ),
                _ => (
                    if *left & RIGHT_WRAPS != 0 {
                        u + 1 - nx
                    } else {
                        u + 1
                    },
                    LEFT,
                ),
            })
        };
        match next {
            None => {
                stack.pop();
                if let Some(&(p, _)) = stack.last() {
                    let p = p as usize;
                    visit[p].low = visit[p].low.min(visit[u].low);
                }
            }
            Some((v, back)) => {
                if visit[v].disc == UNSEEN {
                    visit[v] = Visit {
                        disc: time,
                        low: time,
                    };
                    time += 1;
                    preorder.push((v as u32, u as u32));
                    // The edge back to `u` is the tree edge, passed over once; a second edge
                    // between the same two cells (a wrapped grid of two columns) stays.
                    stack.push((v as u32, edges[v] & !back));
                } else {
                    visit[u].low = visit[u].low.min(visit[v].disc);
                }
            }
        }
    }
    (visit, preorder)
}
