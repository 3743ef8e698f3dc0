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

/// A cell that is not a dead end (on the backbone, or not spanning).
const NONE: u32 = u32::MAX;
/// A dead end hanging off the inlet reservoir (pressure `Δp`).
pub const INLET: u32 = u32::MAX - 1;
/// A dead end hanging off the outlet reservoir (pressure 0).
pub const OUTLET: u32 = u32::MAX - 2;

/// Largest grid (cells) [`anchors`] takes: cell indices below the three markers.
pub const MAX_CELLS: usize = (u32::MAX - 3) as usize;

/// The dead-end cells with their anchors, `(cell, anchor)` by increasing cell (row-major
/// indices): the backbone cell, [`INLET`] or [`OUTLET`] whose pressure the dead end takes. `spanning`: the cells of the spanning clusters on the row-major `ny × nx`
/// grid, flow along axis 0 (inlet before row 0, outlet after row `ny − 1`), wrapped across
/// axis 1 when `periodic`.
pub fn anchors(spanning: &[bool], ny: usize, nx: usize, periodic: bool) -> Vec<(u32, u32)> {
    let n = ny * nx;
    assert!(n <= MAX_CELLS && spanning.len() == n);
    let (inlet, outlet) = (n, n + 1);
    // The neighbours of a vertex, one slot at a time: `Some(None)` an empty slot, `None` done.
    let slot = |u: usize, s: usize| -> Option<Option<usize>> {
        if u >= n {
            // A reservoir: the other reservoir first, then its row's spanning cells.
            let row = if u == inlet { 0 } else { ny - 1 };
            return match s {
                0 => Some(Some(if u == inlet { outlet } else { inlet })),
                s if s <= nx => {
                    let k = row * nx + s - 1;
                    Some(spanning[k].then_some(k))
                }
                _ => None,
            };
        }
        let (i, j) = (u / nx, u % nx);
        let cell = |k: usize| Some(spanning[k].then_some(k));
        match s {
            0 => {
                if i > 0 {
                    cell(u - nx)
                } else {
                    Some(Some(inlet))
                }
            }
            1 => {
                if i + 1 < ny {
                    cell(u + nx)
                } else {
                    Some(Some(outlet))
                }
            }
            2 => {
                if j > 0 {
                    cell(u - 1)
                } else if periodic && nx > 1 {
                    cell(u + nx - 1)
                } else {
                    Some(None)
                }
            }
            3 => {
                if j + 1 < nx {
                    cell(u + 1)
                } else if periodic && nx > 1 {
                    cell(u + 1 - nx)
                } else {
                    Some(None)
                }
            }
            _ => None,
        }
    };
    if !spanning.iter().any(|&s| s) {
        return Vec::new();
    }
    const UNSEEN: u32 = u32::MAX;
    let mut disc = vec![UNSEEN; n + 2];
    let mut low = vec![0u32; n + 2];
    let mut parent = vec![NONE; n + 2];
    // Whether the tree edge to the parent was passed over once (two faces between the same
    // two cells, on a grid wrapped across two columns, are two edges).
    let mut skipped = vec![false; n + 2];
    let mut preorder: Vec<u32> = Vec::new();
    let mut time = 0u32;
    // (vertex, next slot)
    let mut stack: Vec<(u32, u8)> = vec![(inlet as u32, 0)];
    let mut reservoir_slot = [0usize; 2];
    disc[inlet] = time;
    low[inlet] = time;
    time += 1;
    while let Some(&mut (u, ref mut s)) = stack.last_mut() {
        let u = u as usize;
        // A reservoir's slots run past 255: kept apart, one counter each.
        let at = if u >= n {
            reservoir_slot[u - n]
        } else {
            *s as usize
        };
        match slot(u, at) {
            None => {
                stack.pop();
                let p = parent[u];
                if p != NONE {
                    let p = p as usize;
                    low[p] = low[p].min(low[u]);
                }
            }
            Some(next) => {
                if u >= n {
                    reservoir_slot[u - n] += 1;
                } else {
                    *s += 1;
                }
                let Some(v) = next else { continue };
                if disc[v] == UNSEEN {
                    parent[v] = u as u32;
                    disc[v] = time;
                    low[v] = time;
                    time += 1;
                    if v < n {
                        preorder.push(v as u32);
                    }
                    stack.push((v as u32, 0));
                } else if v as u32 == parent[u] && !skipped[u] {
                    skipped[u] = true;
                } else {
                    low[u] = low[u].min(disc[v]);
                }
            }
        }
    }
    // The backbone is the block of the tree edge `I–O` (the inlet's first child is the
    // outlet). A child `c` of `p` shares `p`'s block iff `low(c) < disc(p)`.
    drop(skipped);
    drop(stack);
    // Each cell's anchor, [`NONE`] on the backbone, written over its low point once that is
    // read (in preorder, a parent before its children).
    let mut anchor = low;
    anchor[inlet] = NONE;
    anchor[outlet] = NONE;
    let mut dead = Vec::new();
    for &c in &preorder {
        let (c, p) = (c as usize, parent[c as usize] as usize);
        let a = if p < n && anchor[p] != NONE {
            anchor[p]
        } else if anchor[c] >= disc[p] {
            // `anchor[c]` still holds `low(c)`: the edge `p–c` starts a block of its own.
            match p {
                p if p == inlet => INLET,
                p if p == outlet => OUTLET,
                p => p as u32,
            }
        } else {
            NONE
        };
        anchor[c] = a;
        if a != NONE {
            dead.push((c as u32, a));
        }
    }
    dead.sort_unstable();
    dead
}
