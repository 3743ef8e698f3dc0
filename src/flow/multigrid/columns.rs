//! Column storage of a level's compressed rows: absolute 32-bit columns while the hierarchy
//! is built, and, once a level is complete, each column as its 16-bit offset from the row
//! where every offset fits. Unknowns are numbered in grid order on every level, so a row's
//! faces lie within a few grid rows of it: at 4097² the offsets of `S` stay within about
//! ±2,500. A face then takes 6 bytes instead of 8: the hierarchy of the 4097² gaps is
//! about 100 MiB smaller (synthetic gap: peak 2.29 against 2.40 GiB). The sweeps gain
//! little time (4 % on `S` of a 2049² field, none on the level below; docs/flow.md): they
//! wait on the row-to-row dependence more than on memory.

/// Column `j` of entry `p` in row `i`.
pub(super) trait Columns: Sync {
    /// # Safety
    /// `p` is an entry of row `i` of the rows these columns belong to.
    unsafe fn at(&self, p: usize, i: usize) -> usize;
}

/// Absolute columns.
pub(super) struct Absolute<'a>(pub(super) &'a [u32]);

impl Columns for Absolute<'_> {
    #[inline(always)]
    unsafe fn at(&self, p: usize, _i: usize) -> usize {
        *self.0.get_unchecked(p) as usize
    }
}

/// Columns as offsets from their row, `j − i`.
pub(super) struct Offsets<'a>(pub(super) &'a [i16]);

impl Columns for Offsets<'_> {
    #[inline(always)]
    unsafe fn at(&self, p: usize, i: usize) -> usize {
        from_offset(i, *self.0.get_unchecked(p))
    }
}

/// Column `i + offset`.
#[inline(always)]
pub(super) fn from_offset(i: usize, offset: i16) -> usize {
    i.wrapping_add_signed(isize::from(offset))
}

/// The offsets `j − i` of rows `ptr`/`col`, or `None` when one does not fit in 16 bits.
pub(super) fn offsets(ptr: &[usize], col: &[u32]) -> Option<Vec<i16>> {
    use rayon::prelude::*;
    const ROWS: usize = super::CHUNK;
    let n = ptr.len().saturating_sub(1);
    let offset = |i: usize, j: u32| i16::try_from(i64::from(j) - i as i64);
    let fits = (0..n).into_par_iter().with_min_len(ROWS).all(|i| {
        col[ptr[i]..ptr[i + 1]]
            .iter()
            .all(|&j| offset(i, j).is_ok())
    });
    if !fits {
        return None;
    }
    let mut out = vec![0i16; col.len()];
    // Blocks of rows, each writing its own entries.
    let mut parts = Vec::new();
    let mut rest = &mut out[..];
    for b in (0..n).step_by(ROWS) {
        let (here, tail) = std::mem::take(&mut rest).split_at_mut(ptr[(b + ROWS).min(n)] - ptr[b]);
        parts.push((b, here));
        rest = tail;
    }
    parts.into_par_iter().for_each(|(b, here)| {
        let base = ptr[b];
        for i in b..(b + ROWS).min(n) {
            for q in ptr[i]..ptr[i + 1] {
                here[q - base] = offset(i, col[q]).unwrap_or(0);
            }
        }
    });
    Some(out)
}
