//! The flow's factored two-column solve (`direct::Factor::solve_pair`: the inlet and the
//! outlet right-hand sides at once, forward and backward through the factor) on the rayon
//! pool (all cores unless `RAYON_NUM_THREADS` says otherwise). Prints the factor's size, the
//! median of 9 rounds of 10 solves and a hash of the answer, which is the same for two
//! builds exactly when their solves give the same bits.
//!
//! ```text
//! cargo bench --bench solve_bench                       # 513², random conductances
//! python benchmarks/flow_conductances.py spectral_513_1.01 /tmp/c513.bin
//! SIDE=513 CONDUCTANCES=/tmp/c513.bin cargo bench --bench solve_bench
//! ```
//!
//! `SIDE`: cells per side (default 513). `CONDUCTANCES`: a file of `SIDE²` little-endian
//! `f64` cell conductances in row-major order, 0 for closed cells
//! (`benchmarks/flow_conductances.py` writes those of a cached contact gap: only cells of
//! clusters that join the first and the last row open); without it, every cell open with a
//! conductance drawn over six decades. Wrapped across, flow
//! along the rows. To compare two commits, copy this file into the other checkout and run
//! it there too.

use std::time::Instant;

#[path = "bench_support.rs"]
mod bench_support;
use bench_support::{grid_conductances, Uniform};

use leakpath::flow::assemble::fine_stencil;
use leakpath::flow::direct::Factor;

fn main() {
    let mut seq = Uniform::new(0x2545_f491_4f6c_dd1d);
    let (side, c) = grid_conductances(513, &mut seq);
    let n = side * side;
    let (st, b_in) = fine_stencil(&c, side, side, true);
    // The outlet's right-hand side: the inlet's, rows reversed.
    let b_out: Vec<f64> = (0..n)
        .map(|k| b_in[(side - 1 - k / side) * side + k % side])
        .collect();
    let t = Instant::now();
    let mut f = Factor::new(&st, None).expect("a factor");
    let setup = t.elapsed().as_secs_f64();
    let (mut x, mut psi) = (vec![0.0; n], vec![0.0; n]);
    f.solve_pair(&b_in, &b_out, &mut x, &mut psi);
    let mut ms: Vec<f64> = (0..9)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..10 {
                f.solve_pair(&b_in, &b_out, &mut x, &mut psi);
            }
            t.elapsed().as_secs_f64() * 1e3 / 10.0
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    let hash = x.iter().chain(&psi).fold(0xcbf2_9ce4_8422_2325u64, |h, v| {
        (h ^ v.to_bits()).wrapping_mul(0x0100_0000_01b3)
    });
    println!(
        "two-column solve of {side}² cells ({} entries in the factor, factored in {setup:.2} \
         s), {} threads: median {:.3} ms (rounds {:.3}–{:.3} ms), answer hash {hash:016x}",
        f.entries(),
        rayon::current_num_threads(),
        ms[4],
        ms[0],
        ms[8]
    );
}
