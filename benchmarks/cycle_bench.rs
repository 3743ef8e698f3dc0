//! One cycle of the flow's multigrid preconditioner (`Multigrid::cycle`, from 0 on the
//! Schur complement `S`: the W-cycle on the top two levels, the V-cycle below) on the rayon
//! pool (all cores unless `RAYON_NUM_THREADS` says otherwise). Prints the median of 9
//! rounds of 5 cycles and a hash of the cycle's result, which is the same for two builds
//! exactly when their cycles give the same bits.
//!
//! ```text
//! cargo bench --bench cycle_bench                       # 2049², random conductances
//! python benchmarks/flow_conductances.py spectral_4097_1.01 /tmp/c4097.bin
//! SIDE=4097 CONDUCTANCES=/tmp/c4097.bin cargo bench --bench cycle_bench
//! ```
//!
//! `SIDE`: cells per side (default 2049). `CONDUCTANCES`: a file of `SIDE²` little-endian
//! `f64` cell conductances in row-major order, 0 for closed cells, every open cell in a
//! cluster joining the first and the last row (`benchmarks/flow_conductances.py` writes
//! those of a cached contact gap); without it, every cell open with a conductance drawn over
//! six decades. Wrapped across, flow along the rows. To compare two commits, copy this file
//! into the other checkout and run it there too.

use std::time::Instant;

#[path = "bench_support.rs"]
mod bench_support;
use bench_support::{grid_conductances, Uniform};

use leakpath::flow::assemble::fine_stencil;
use leakpath::flow::multigrid::Multigrid;

fn main() {
    let mut seq = Uniform::new(0x2545_f491_4f6c_dd1d);
    let (side, c) = grid_conductances(2049, &mut seq);
    let (st, _) = fine_stencil(&c, side, side, true);
    let t = Instant::now();
    let mg = Multigrid::new(st);
    let setup = t.elapsed().as_secs_f64();
    let m = mg.reduced_len().expect("a grid large enough to reduce");
    let s: Vec<f64> = (0..m).map(|_| seq.next() - 0.5).collect();
    let mut z = vec![0.0; m];
    let mut ms: Vec<f64> = (0..9)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..5 {
                mg.cycle(&s, &mut z);
            }
            t.elapsed().as_secs_f64() * 1e3 / 5.0
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    assert!(
        z.iter().all(|v| v.is_finite()),
        "the cycle's result is finite"
    );
    let hash = z.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, v| {
        (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
    });
    println!(
        "cycle on S of {side}² cells ({m} unknowns, {} levels, setup {setup:.2} s), {} \
         threads: median {:.2} ms (rounds {:.2}–{:.2} ms), result hash {hash:016x}",
        mg.n_levels(),
        rayon::current_num_threads(),
        ms[4],
        ms[0],
        ms[8],
    );
}
