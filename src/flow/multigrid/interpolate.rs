//! Classical interpolation with lumping, from the strong C neighbours of each F unknown.

use rayon::prelude::*;

use super::rows::Rows;
use super::{check_rows, concat, strong, Interp, RowBlock, CHUNK, NONE};

/// Classical interpolation (module docs) and the row-sum deficits `δ_i = dir_i / den`.
pub(super) fn interpolation(
    g: &impl Rows,
    wmax: &[f64],
    cidx: &[u32],
    nc: usize,
) -> (Interp, Vec<f64>) {
    let n = g.n();
    let blocks: Vec<RowBlock> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|blk| {
            let rows = blk * CHUNK..((blk + 1) * CHUNK).min(n);
            let mut len = Vec::with_capacity(rows.len());
            let mut col = Vec::new();
            let mut val = Vec::new();
            let mut delta = Vec::with_capacity(rows.len());
            let mut row: Vec<(u32, f64)> = Vec::new();
            for i in rows {
                if cidx[i] != NONE {
                    len.push(1);
                    col.push(cidx[i]);
                    val.push(1.0);
                    delta.push(0.0);
                    continue;
                }
                row.clear();
                let dir = g.reservoir(i);
                let mut den = dir;
                // Strong C neighbours first (their fine index and w_ij).
                for (j, wij) in g.row(i) {
                    if strong(wij, wmax[i]) && cidx[j as usize] != NONE {
                        row.push((j, wij));
                        den += wij;
                    }
                }
                if row.is_empty() {
                    len.push(0);
                    delta.push(1.0);
                    continue;
                }
                // Strong F neighbours: distributed over the strong C neighbours of i.
                for (k, wik) in g.row(i) {
                    let k = k as usize;
                    if !strong(wik, wmax[i]) || cidx[k] != NONE {
                        continue;
                    }
                    let mut sum = 0.0;
                    for e in row.iter() {
                        let wkm = g.weight(k, e.0);
                        if wkm > 0.0 {
                            sum += wkm;
                        }
                    }
                    if sum > 0.0 {
                        den += wik;
                        let share = wik / sum;
                        for e in row.iter_mut() {
                            let wkm = g.weight(k, e.0);
                            if wkm > 0.0 {
                                e.1 += share * wkm;
                            }
                        }
                    }
                }
                len.push(row.len());
                for &(j, v) in row.iter() {
                    col.push(cidx[j as usize]);
                    val.push((v / den) as f32);
                }
                delta.push(dir / den);
            }
            (len, col, val, delta)
        })
        .collect();
    let (ptr, col, val, deltas) = concat(blocks);
    // Transpose by counting (rows of each coarse column ascending).
    let mut tptr = vec![0usize; nc + 1];
    for &c in &col {
        tptr[c as usize + 1] += 1;
    }
    for c in 0..nc {
        tptr[c + 1] += tptr[c];
    }
    let mut fill = tptr[..nc].to_vec();
    let mut trow = vec![0u32; col.len()];
    let mut tval = vec![0.0f32; col.len()];
    for i in 0..n {
        for p in ptr[i]..ptr[i + 1] {
            let c = col[p] as usize;
            trow[fill[c]] = i as u32;
            tval[fill[c]] = val[p];
            fill[c] += 1;
        }
    }
    assert_eq!(val.len(), col.len(), "a weight per column");
    check_rows(&ptr, &col, n, nc);
    check_rows(&tptr, &trow, nc, n);
    (
        Interp {
            ptr,
            col,
            val,
            tptr,
            trow,
            tval,
        },
        deltas,
    )
}
