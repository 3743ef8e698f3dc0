//! An ordering and symbolic analysis kept from one flow to the next: the levels of a contact
//! sweep close a few more cells each, so a level's unknowns are usually among the previous
//! level's, and its factor can be computed on that level's analysis ([`Factor::new_reusing`],
//! identity rows for the cells that closed) without ordering and analysing again.
//!
//! A flow given a [`KeptAnalysis`] uses the kept analysis when it fits (same grid, its
//! unknowns among the analysis's and at least [`REUSE_FRACTION`] of them), else analyses
//! afresh and keeps the new one. The rate differs from a fresh analysis's by round-off only;
//! which analysis a flow uses depends on the flows solved before it with the same object,
//! so a caller that wants the same bits on every run solves them in the same order.
//!
//! [`Factor::new_reusing`]: super::direct::Factor::new_reusing
//! [`REUSE_FRACTION`]: super::direct::REUSE_FRACTION

use std::sync::{Arc, Mutex};

use super::direct::Analysis;

/// Grids below this many cells (1024²) analyse afresh by default: their analysis costs
/// little beside the factor.
pub const DEFAULT_MIN_CELLS: usize = 1 << 20;

/// The analysis kept between flows, and counts of the flows that made or reused one.
pub struct KeptAnalysis {
    min_cells: usize,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    kept: Option<Arc<Analysis>>,
    made: usize,
    reused: usize,
}

impl KeptAnalysis {
    /// An empty slot; flows on grids of fewer than `min_cells` cells do not use it.
    pub fn new(min_cells: usize) -> Self {
        KeptAnalysis {
            min_cells,
            state: Mutex::new(State::default()),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, State> {
        // A panic elsewhere cannot leave the slot half-written: keep using it.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether flows on a grid of `cells` cells use the slot.
    pub fn applies(&self, cells: usize) -> bool {
        cells >= self.min_cells
    }

    /// The kept analysis, if any.
    pub fn get(&self) -> Option<Arc<Analysis>> {
        self.lock().kept.clone()
    }

    /// Records the analysis a factor used: `reused` (it was the kept one) or new (kept from
    /// now on, the previous one dropped).
    pub fn keep(&self, analysis: &Arc<Analysis>, reused: bool) {
        let mut s = self.lock();
        if reused {
            s.reused += 1;
        } else {
            s.made += 1;
            s.kept = Some(analysis.clone());
        }
    }

    /// Drops the kept analysis (its memory); the counts stay.
    pub fn clear(&self) {
        self.lock().kept = None;
    }

    /// Flows that made a new analysis.
    pub fn made(&self) -> usize {
        self.lock().made
    }

    /// Flows that factored on the kept analysis.
    pub fn reused(&self) -> usize {
        self.lock().reused
    }

    /// Unknowns of the kept analysis (0 without one).
    pub fn unknowns(&self) -> usize {
        self.lock().kept.as_ref().map_or(0, |a| a.unknowns())
    }

    /// Entries of a factor on the kept analysis (0 without one).
    pub fn entries(&self) -> usize {
        self.lock().kept.as_ref().map_or(0, |a| a.entries())
    }
}
