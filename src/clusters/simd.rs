//! The kernels of the strip pass behind one dispatch (`const AVX2: bool`, chosen once per
//! run): run boundaries of a row's bit mask and the per-run gap sums, portable and AVX2. Both
//! variants produce the same numbers (the AVX2 sum adds the same terms in the same order).

use super::*;

/// Σ `gap[s..e]` (`s < e`) in index order.
///
/// Most runs of a random mask are short, so the first eight terms are always loaded and
/// masked by all-ones or zero bits from a table: no data-dependent branch (a `select` would be
/// compiled to one, which mispredicts). A masked-out term is `+0.0` whatever the cell holds,
/// and `x + 0.0 == x`: the result is the plain sequential sum.
#[inline(always)]
pub(super) fn run_sum(gap: &[f64], s: usize, e: usize) -> f64 {
    const W: usize = 8;
    static MASKS: [[u64; W]; W + 1] = {
        let mut t = [[0u64; W]; W + 1];
        let mut n = 0;
        while n <= W {
            let mut k = 0;
            while k < n {
                t[n][k] = u64::MAX;
                k += 1;
            }
            n += 1;
        }
        t
    };
    match gap.get(s..s + W) {
        Some(v) => {
            let m = &MASKS[(e - s).min(W)];
            let mut acc = f64::from_bits(v[0].to_bits() & m[0]);
            for k in 1..W {
                acc += f64::from_bits(v[k].to_bits() & m[k]);
            }
            for &x in gap.get(s + W..e).unwrap_or(&[]) {
                acc += x;
            }
            acc
        }
        None => gap[s + 1..e].iter().fold(gap[s], |acc, &x| acc + x),
    }
}

/// Writes the cells and Σ gap of each run of row `cur` to `out[done..]`, growing it if needed
/// (it is never shrunk, so that it is not zero-filled again for every strip). `gap` is the
/// whole gap field and `start` the row's first cell in it; `pos` is scratch. `AVX2`: the CPU
/// has AVX2.
#[inline(always)]
pub(super) fn row_sums<const AVX2: bool>(
    cur: &RowBits,
    gap: &[f64],
    start: usize,
    pos: &mut Vec<u32>,
    done: usize,
    out: &mut Vec<[f64; 2]>,
) {
    let runs = cur.runs as usize;
    grow(pos, 2 * runs + 8);
    grow(out, done + runs);
    // Run boundaries: each run's first cell and the cell after its last one, alternating.
    // The bits past the row's end are zero, so the last run's end is found too, unless the
    // row ends at a word's end.
    let n = boundaries::<AVX2>(&cur.bits, pos);
    if n < 2 * runs {
        pos[n] = 64 * cur.bits.len() as u32;
    }
    let pos = &pos[..2 * runs];
    let out = &mut out[done..done + runs];
    let mut i = 0;
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is set only on CPUs with AVX2 (see `label_strip_fast`).
        i = unsafe { row_sums_avx2(&gap[start..], pos, out) };
    }
    for (o, se) in out[i..].iter_mut().zip(pos[2 * i..].chunks_exact(2)) {
        let (s, e) = (start + se[0] as usize, start + se[1] as usize);
        *o = [(e - s) as f64, run_sum(gap, s, e)];
    }
}

/// Writes the positions of the run boundaries of the row `bits`, the cells that differ from
/// their left neighbour, to `pos`, in order, and returns how many there are. `pos` must have
/// room for eight more than that.
#[inline(always)]
pub(super) fn boundaries<const AVX2: bool>(bits: &[u64], pos: &mut [u32]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: `AVX2` is set only on CPUs with AVX2 (see `label_strip_fast`).
        return unsafe { boundaries_avx2(bits, pos) };
    }
    let (mut n, mut carry) = (0, 0);
    for (k, &b) in bits.iter().enumerate() {
        let mut t = b ^ ((b << 1) | carry);
        carry = b >> 63;
        while t != 0 {
            pos[n] = 64 * k as u32 + t.trailing_zeros();
            n += 1;
            t &= t - 1;
        }
    }
    n
}

/// Offsets of the set bits of each byte value, lowest first (the rest of each entry is 0).
#[cfg(target_arch = "x86_64")]
pub(super) static BIT_POS: [[u8; 8]; 256] = {
    let mut t = [[0u8; 8]; 256];
    let mut m = 0;
    while m < 256 {
        let (mut k, mut n) = (0, 0);
        while k < 8 {
            if (m >> k) & 1 == 1 {
                t[m][n] = k as u8;
                n += 1;
            }
            k += 1;
        }
        m += 1;
    }
    t
};

/// [`boundaries`], eight cells at a time from a table of the set bits of each byte: no
/// data-dependent branch, while a loop over set bits ends after a data-dependent count and
/// mispredicts.
///
/// # Safety
///
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn boundaries_avx2(bits: &[u64], pos: &mut [u32]) -> usize {
    use std::arch::x86_64::*;
    let (mut n, mut carry) = (0, 0);
    for (k, &b) in bits.iter().enumerate() {
        let t = b ^ ((b << 1) | carry);
        carry = b >> 63;
        for (j, m) in t.to_le_bytes().into_iter().enumerate() {
            let dst = &mut pos[n..n + 8];
            // SAFETY: the table entry has 8 bytes and `dst` 8 entries.
            unsafe {
                let offsets = _mm_loadl_epi64(BIT_POS[m as usize].as_ptr().cast());
                let base = _mm256_set1_epi32((64 * k + 8 * j) as i32);
                let v = _mm256_add_epi32(_mm256_cvtepu8_epi32(offsets), base);
                _mm256_storeu_si256(dst.as_mut_ptr().cast(), v);
            }
            n += m.count_ones() as usize;
        }
    }
    n
}

/// The cells and [`run_sum`] of the runs `pos[2i]..pos[2i + 1]` of `gap` into `out[i]`, four
/// runs at a time: the first eight cells of four runs are loaded, transposed so that each
/// vector holds the `k`-th cell of the four runs, masked beyond each run's end and added up in
/// order, lane by lane, so each lane is the sequential sum of its run. Returns how many runs it
/// did, from the first; it stops where the next four runs' windows would pass the end of
/// `gap`.
///
/// # Safety
///
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn row_sums_avx2(gap: &[f64], pos: &[u32], out: &mut [[f64; 2]]) -> usize {
    use std::arch::x86_64::*;
    const W: usize = 8;
    let n = (pos.len() / 2).min(out.len());
    let mut i = 0;
    while i + 4 <= n && (pos[2 * i + 6] as usize) + W <= gap.len() {
        let se = &pos[2 * i..2 * i + 8];
        let s = [se[0], se[2], se[4], se[6]].map(|x| x as usize);
        // SAFETY: `s[k] + W <= gap.len()` for every k (the starts increase); `se` and
        // `out[i..i + 4]` are in bounds.
        unsafe {
            let p = gap.as_ptr();
            // The loop reads the row from main memory: ask for it ahead of use.
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(s[0] + 256).cast());
            _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(s[0] + 264).cast());
            // Cells `o..o + 4` of the four runs, transposed: `c[j]` holds cell `o + j` of each.
            let mut c = [_mm256_setzero_pd(); W];
            for o in [0, 4] {
                let a0 = _mm256_loadu_pd(p.add(s[0] + o));
                let a1 = _mm256_loadu_pd(p.add(s[1] + o));
                let a2 = _mm256_loadu_pd(p.add(s[2] + o));
                let a3 = _mm256_loadu_pd(p.add(s[3] + o));
                let t0 = _mm256_unpacklo_pd(a0, a1);
                let t1 = _mm256_unpackhi_pd(a0, a1);
                let t2 = _mm256_unpacklo_pd(a2, a3);
                let t3 = _mm256_unpackhi_pd(a2, a3);
                c[o] = _mm256_permute2f128_pd::<0x20>(t0, t2);
                c[o + 1] = _mm256_permute2f128_pd::<0x20>(t1, t3);
                c[o + 2] = _mm256_permute2f128_pd::<0x31>(t0, t2);
                c[o + 3] = _mm256_permute2f128_pd::<0x31>(t1, t3);
            }
            // Starts in the low half, ends in the high half.
            let v = _mm256_loadu_si256(se.as_ptr().cast());
            let v = _mm256_permutevar8x32_epi32(v, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7));
            let len32 = _mm_sub_epi32(_mm256_extracti128_si256::<1>(v), _mm256_castsi256_si128(v));
            let cells = _mm256_cvtepi32_pd(len32);
            // Every run has at least one cell.
            let mut acc = c[0];
            for (k, &v) in c.iter().enumerate().skip(1) {
                let m = _mm256_cmp_pd::<_CMP_GT_OQ>(cells, _mm256_set1_pd(k as f64));
                acc = _mm256_add_pd(acc, _mm256_and_pd(v, m));
            }
            let long =
                _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(cells, _mm256_set1_pd(W as f64)));
            if long != 0 {
                let mut a = [0.0; 4];
                _mm256_storeu_pd(a.as_mut_ptr(), acc);
                for (k, a) in a.iter_mut().enumerate() {
                    let e = se[2 * k + 1] as usize;
                    for &x in &gap[(s[k] + W).min(e)..e] {
                        *a += x;
                    }
                }
                acc = _mm256_loadu_pd(a.as_ptr());
            }
            // Interleaved with the cell counts: [cells, Σ gap] per run.
            let lo = _mm256_unpacklo_pd(cells, acc);
            let hi = _mm256_unpackhi_pd(cells, acc);
            let o = out.as_mut_ptr().add(i).cast::<f64>();
            _mm256_storeu_pd(o, _mm256_permute2f128_pd::<0x20>(lo, hi));
            _mm256_storeu_pd(o.add(4), _mm256_permute2f128_pd::<0x31>(lo, hi));
        }
        i += 4;
    }
    i
}
