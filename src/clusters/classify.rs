//! Percolation classes of the clusters for a flow direction (spanning, dead-end, trapped) and
//! the class totals, summed with Neumaier compensation.

use super::*;

/// Neumaier's compensated sum: exact to a few ulps of the result for sums of like-signed terms.
#[derive(Clone, Copy, Default)]
struct Compensated {
    sum: f64,
    c: f64,
}

impl Compensated {
    fn add(&mut self, v: f64) {
        let t = self.sum + v;
        if self.sum.abs() >= v.abs() {
            self.c += (self.sum - t) + v;
        } else {
            self.c += (v - t) + self.sum;
        }
        self.sum = t;
    }
    fn value(self) -> f64 {
        self.sum + self.c
    }
}

/// Percolation classes of the clusters and the class totals.
#[derive(Clone, Debug, PartialEq)]
pub struct Classification {
    pub flow: Flow,
    /// `SPANNING`, `DEAD_END` or `TRAPPED` per cluster (entry `k − 1` for label `k`).
    pub classes: Vec<u8>,
    /// Volumes (length³) of spanning (`V_pg`), dead-end and trapped clusters, and of all free
    /// cells; each is a compensated sum over clusters, so the three add up to `free_volume` to
    /// within a few ulps.
    pub spanning_volume: f64,
    pub dead_end_volume: f64,
    pub trapped_volume: f64,
    pub free_volume: f64,
    /// Cell counts of the same sets.
    pub spanning_area: u64,
    pub dead_end_area: u64,
    pub trapped_area: u64,
    pub free_area: u64,
    pub n_spanning: usize,
    pub n_dead_end: usize,
    pub n_trapped: usize,
}

/// Class of a cluster with touch flags `t` (see the module docs).
pub fn class_of(t: u8, flow: Flow, periodic: Periodic) -> u8 {
    let rows = TOUCH_FIRST_ROW | TOUCH_LAST_ROW;
    let cols = TOUCH_FIRST_COL | TOUCH_LAST_COL;
    // A wrapped axis has no boundary.
    let boundary =
        (if periodic.axis0 { 0 } else { rows }) | (if periodic.axis1 { 0 } else { cols });
    let span0 = !periodic.axis0 && t & rows == rows;
    let span1 = !periodic.axis1 && t & cols == cols;
    let spans = match flow {
        Flow::Axis0 => span0,
        Flow::Axis1 => span1,
        Flow::Either => span0 || span1,
        Flow::Both => span0 && span1,
    };
    if spans {
        SPANNING
    } else if t & boundary != 0 {
        DEAD_END
    } else {
        TRAPPED
    }
}

/// Classifies the clusters for flow along `flow` (see the module docs).
///
/// Each class's sums and the free volume are taken in a pass of their own, the four in
/// parallel: every compensated sum still adds its volumes in cluster order, so the totals do
/// not depend on the thread count.
pub fn classify(clusters: &Clusters, flow: Flow) -> Result<Classification> {
    flow.check_periodic(clusters.periodic)?;
    let table: [u8; 16] = std::array::from_fn(|t| class_of(t as u8, flow, clusters.periodic));
    let classes: Vec<u8> = clusters
        .touches
        .par_iter()
        .map(|&t| table[usize::from(t & 15)])
        .collect();
    let volumes = &clusters.volumes;
    // Volume, cells and count of the clusters of class `want`.
    let of_class = |want: u8| {
        let (mut vol, mut area, mut count) = (Compensated::default(), 0u64, 0usize);
        for ((&c, &v), &a) in classes.iter().zip(volumes).zip(&clusters.areas) {
            if c == want {
                vol.add(v);
                area += a;
                count += 1;
            }
        }
        (vol.value(), area, count)
    };
    let total = || {
        let mut total = Compensated::default();
        for &v in volumes {
            total.add(v);
        }
        total.value()
    };
    let ((spanning, dead_end), (trapped, free_volume)) = rayon::join(
        || rayon::join(|| of_class(SPANNING), || of_class(DEAD_END)),
        || rayon::join(|| of_class(TRAPPED), total),
    );
    Ok(Classification {
        flow,
        classes,
        spanning_volume: spanning.0,
        dead_end_volume: dead_end.0,
        trapped_volume: trapped.0,
        free_volume,
        spanning_area: spanning.1,
        dead_end_area: dead_end.1,
        trapped_area: trapped.1,
        free_area: spanning.1 + dead_end.1 + trapped.1,
        n_spanning: spanning.2,
        n_dead_end: dead_end.2,
        n_trapped: trapped.2,
    })
}
