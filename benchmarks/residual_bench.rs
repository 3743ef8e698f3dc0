//! The flow's double-double residual `b − A x` (`Stencil::residual_compensated`, and
//! `residual_split` for `x = hi + lo`) on a 513² grid: 70 % open cells with conductances
//! over six decades, wrapped across, on the rayon pool (all cores unless
//! `RAYON_NUM_THREADS` says otherwise). Prints the median of 7 rounds of 50 calls each.
//!
//! ```text
//! cargo bench --bench residual_bench
//! ```
//!
//! To compare two commits, copy this file into the other checkout and run it there too.

use std::time::Instant;

#[path = "bench_support.rs"]
mod bench_support;
use bench_support::Uniform;

use leakpath::flow::assemble::fine_stencil;

fn main() {
    let (ny, nx) = (513, 513);
    let n = ny * nx;
    let mut seq = Uniform::new(0x2545_f491_4f6c_dd1d);
    let mut uniform = || seq.next();
    let c: Vec<f64> = (0..n)
        .map(|_| {
            if uniform() < 0.3 {
                0.0
            } else {
                10f64.powf(-6.0 * uniform())
            }
        })
        .collect();
    let (st, rhs) = fine_stencil(&c, ny, nx, true);
    let hi: Vec<f64> = (0..n).map(|_| uniform()).collect();
    let lo: Vec<f64> = hi.iter().map(|v| v * 1e-17).collect();
    let mut r = vec![0.0; n];
    let threads = rayon::current_num_threads();
    for split in [false, true] {
        let mut ms: Vec<f64> = (0..7)
            .map(|_| {
                let t = Instant::now();
                for _ in 0..50 {
                    if split {
                        st.residual_split(&hi, &lo, &rhs, &mut r);
                    } else {
                        st.residual_compensated(&hi, &rhs, &mut r);
                    }
                }
                t.elapsed().as_secs_f64() * 1e3 / 50.0
            })
            .collect();
        ms.sort_by(f64::total_cmp);
        println!(
            "residual of {ny}² cells, x in {} double(s), {threads} threads: median {:.3} ms \
             (rounds {:.3}–{:.3} ms)",
            if split { 2 } else { 1 },
            ms[3],
            ms[0],
            ms[6]
        );
    }
}
