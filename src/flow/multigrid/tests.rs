use super::*;
use crate::flow::assemble::fine_stencil;

/// Uniform numbers in `[0, 1)` from a fixed linear congruential sequence.
fn uniform(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

/// A periodic `ny × nx` stencil with cell conductances spanning six decades.
fn rough(seed: u64, ny: usize, nx: usize) -> Stencil {
    let c: Vec<f64> = uniform(seed, ny * nx)
        .iter()
        .map(|u| 10f64.powf(-6.0 * u))
        .collect();
    fine_stencil(&c, ny, nx, true).0
}

#[test]
fn every_strong_f_pair_shares_a_c_neighbour() {
    for seed in 0..3 {
        let st = rough(seed, 60, 50);
        let (g, _, _) = fine_graph(&st);
        let wmax = strongest(&g);
        let (cidx, nc) = split(&g, &wmax);
        assert!(nc > 0 && nc < g.n);
        for i in (0..g.n).filter(|&i| cidx[i] == NONE) {
            let row = g.ptr[i]..g.ptr[i + 1];
            let ci: Vec<u32> = row
                .clone()
                .filter(|&p| strong(g.w[p], wmax[i]) && cidx[g.col[p] as usize] != NONE)
                .map(|p| g.col[p])
                .collect();
            assert!(!ci.is_empty(), "F unknown {i} has no strong C neighbour");
            for p in row {
                let k = g.col[p] as usize;
                if cidx[k] == NONE && strong(g.w[p], wmax[i]) {
                    assert!(
                        ci.iter().any(|&m| g.weight(k, m) > 0.0),
                        "strong F pair {i}, {k} without a common C neighbour"
                    );
                }
            }
        }
    }
}

#[test]
fn cycle_is_symmetric_and_positive() {
    let (ny, nx) = (60, 50);
    let mg = Multigrid::new(rough(7, ny, nx));
    assert!(mg.n_levels() >= 2);
    let n = ny * nx;
    let u: Vec<f64> = uniform(1, n).iter().map(|v| v - 0.5).collect();
    let v: Vec<f64> = uniform(2, n).iter().map(|v| v - 0.5).collect();
    let (mut mu, mut mv) = (vec![0.0; n], vec![0.0; n]);
    mg.apply(&u, &mut mu);
    mg.apply(&v, &mut mv);
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let (a, b) = (dot(&u, &mv), dot(&v, &mu));
    let scale = dot(&u, &u).sqrt() * dot(&mv, &mv).sqrt();
    assert!((a - b).abs() <= 1e-12 * scale, "u·Mv = {a}, v·Mu = {b}");
    assert!(dot(&u, &mu) > 0.0 && dot(&v, &mv) > 0.0);
}
