//! The supernodal symbolic analysis of a sparse Cholesky factor `A = L Lᵀ` in the matrix's
//! own order, and the layout of a supernodal factor's values.
//!
//! The layout is faer's (`SymbolicSupernodalCholesky`): supernode `s` holds the columns
//! `begin[s]..begin[s + 1]`, the rows of its pattern below them (ascending) are
//! `rows[rptr[s]..rptr[s + 1]]`, and its values a dense column-major block of
//! `ncols + pattern` rows at `vptr[s]..vptr[s + 1]`. [`Supernodes::analyse`] computes the
//! same structure as faer's `factorize_symbolic_cholesky` with a custom identity order and
//! the default supernode relaxation (tested: every array equal), in less time and memory:
//!
//! 1. the elimination tree (Liu: each row's entries walked to their roots, with path
//!    compression) and its postorder;
//! 2. the column counts `|L_j|` from the row subtrees' leaves and their least common
//!    ancestors (Gilbert, Ng and Peyton, 1994), in `O(nnz(A) α(n))` instead of a walk over
//!    every entry of `L`;
//! 3. the fundamental supernodes (column `j` joins `j − 1` when it is `j − 1`'s parent, its
//!    only child, and `|L_{j−1}| = |L_j| + 1`), and each merged with the one before it when
//!    that is its child and the explicit zeros the merge adds stay within [`RELAX`];
//! 4. each supernode's pattern: row `k` of `L` is the set of supernodes met walking up the
//!    supernodal tree from each `i < k` with `A_ki ≠ 0` until `k`'s own; `k` is appended to
//!    each, so the patterns come out sorted.
//!
//! faer's analysis also builds a permuted copy of the matrix, a row-major copy of the
//! supernodal pattern and a postorder of the supernodes, which the factor of
//! [`super::supernodal`] and the substitutions of [`super::substitution`] do not read.

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

/// Supernode relaxation: two supernodes of `n` columns in all whose merged block would
/// hold a fraction `z` of explicit zeros merge when `n ≤ c.0` and `z ≤ c.1` for some `c`
/// (faer's defaults, so that both analyses agree).
const RELAX: [(usize, f64); 4] = [(4, 1.0), (16, 0.8), (48, 0.1), (usize::MAX, 0.05)];

const NONE: usize = usize::MAX;

/// A supernodal factor's structure (see the module's documentation), borrowed from
/// [`Supernodes`] or from faer's analysis.
#[derive(Clone, Copy)]
pub(super) struct Layout<'a> {
    n: usize,
    begin: &'a [usize],
    end: &'a [usize],
    rptr: &'a [usize],
    vptr: &'a [usize],
    rows: &'a [usize],
}

impl<'a> Layout<'a> {
    /// The layout of faer's supernodal analysis.
    pub(super) fn of_faer(sn: &'a SymbolicSupernodalCholesky<usize>) -> Self {
        Layout {
            n: sn.nrows(),
            begin: sn.supernode_begin(),
            end: sn.supernode_end(),
            rptr: sn.col_ptr_for_row_idx(),
            vptr: sn.col_ptr_for_val(),
            rows: sn.row_idx(),
        }
    }

    /// Columns (and rows) of the factor.
    #[inline]
    pub(super) fn nrows(&self) -> usize {
        self.n
    }

    #[inline]
    pub(super) fn n_supernodes(&self) -> usize {
        self.begin.len()
    }

    /// First column of each supernode.
    #[inline]
    pub(super) fn supernode_begin(&self) -> &'a [usize] {
        self.begin
    }

    /// One past the last column of each supernode.
    #[inline]
    pub(super) fn supernode_end(&self) -> &'a [usize] {
        self.end
    }

    /// Where each supernode's pattern starts in [`Layout::row_idx`] (one more entry: the end).
    #[inline]
    pub(super) fn col_ptr_for_row_idx(&self) -> &'a [usize] {
        self.rptr
    }

    /// Multiply-adds of the numeric factor's supernodes that start before column `end`:
    /// `Σ (entries of the column, its diagonal's included)²` over their columns.
    pub(super) fn flops_before(&self, end: usize) -> f64 {
        (0..self.n_supernodes())
            .filter(|&s| self.begin[s] < end)
            .map(|s| {
                let nc = self.end[s] - self.begin[s];
                let nr = nc + self.rptr[s + 1] - self.rptr[s];
                (0..nc).map(|c| ((nr - c) * (nr - c)) as f64).sum::<f64>()
            })
            .sum()
    }

    /// Where each supernode's block starts in the values (one more entry: the end).
    #[inline]
    pub(super) fn col_ptr_for_val(&self) -> &'a [usize] {
        self.vptr
    }

    /// The supernodes' patterns, one after the other, each ascending.
    #[inline]
    pub(super) fn row_idx(&self) -> &'a [usize] {
        self.rows
    }

    /// Values of the factor (the supernodes' blocks, explicit zeros included).
    #[inline]
    pub(super) fn len_val(&self) -> usize {
        self.vptr[self.begin.len()]
    }
}

/// The supernodal structure of `L` computed by [`Supernodes::analyse`].
pub(super) struct Supernodes {
    n: usize,
    /// First column of each supernode, then `n`.
    begin: Vec<usize>,
    rptr: Vec<usize>,
    vptr: Vec<usize>,
    rows: Vec<usize>,
}

impl Supernodes {
    /// The structure of the Cholesky factor of the `n × n` symmetric matrix whose lower
    /// triangle has, in column `j`, the rows `row_idx[col_ptr[j]..col_ptr[j + 1]]` (each at
    /// least `j`, in any order; the diagonal may be absent), eliminated in its own order,
    /// with no supernode holding both column `split − 1` and column `split` (`n`: no such
    /// boundary; a factor in halves stops its numeric factor there, [`super::halves`]).
    /// `Err`: the pattern is not such a lower triangle, or the factor's size overflows.
    pub(super) fn analyse(
        n: usize,
        col_ptr: &[usize],
        row_idx: &[usize],
        split: usize,
    ) -> Result<Self, &'static str> {
        if col_ptr.len() != n + 1
            || col_ptr[0] != 0
            || col_ptr.windows(2).any(|w| w[0] > w[1])
            || col_ptr[n] > row_idx.len()
        {
            return Err("the column pointers of the symbolic analysis do not fit the matrix");
        }
        for j in 0..n {
            if row_idx[col_ptr[j]..col_ptr[j + 1]]
                .iter()
                .any(|&i| i < j || i >= n)
            {
                return Err("the symbolic analysis's matrix is not a lower triangle");
            }
        }
        // The strict upper triangle by columns (row `k` of the lower one), rows ascending.
        let mut up_ptr = vec![0usize; n + 1];
        for j in 0..n {
            for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
                if i > j {
                    up_ptr[i + 1] += 1;
                }
            }
        }
        for k in 0..n {
            up_ptr[k + 1] += up_ptr[k];
        }
        let mut up_idx = vec![0usize; up_ptr[n]];
        let mut fill = up_ptr[..n].to_vec();
        for j in 0..n {
            for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
                if i > j {
                    up_idx[fill[i]] = j;
                    fill[i] += 1;
                }
            }
        }
        drop(fill);
        let upper = |k: usize| &up_idx[up_ptr[k]..up_ptr[k + 1]];
        let lower = |j: usize| &row_idx[col_ptr[j]..col_ptr[j + 1]];

        let parent = elimination_tree(n, upper);
        let post = postorder(&parent);
        let counts = column_counts(&parent, &post, lower);
        drop(post);
        // A column's count includes its diagonal and at most every row below it.
        if counts.iter().enumerate().any(|(j, &c)| c == 0 || c > n - j) {
            return Err("the symbolic analysis's column counts are out of range");
        }

        // Fundamental supernodes.
        let mut children = vec![0u32; n];
        for &p in &parent {
            if p != NONE {
                children[p] += 1;
            }
        }
        let mut size: Vec<usize> = Vec::new();
        for j in 0..n {
            let joins = j > 0
                && j != split
                && parent[j - 1] == j
                && children[j] == 1
                && counts[j - 1] == counts[j] + 1;
            if joins {
                *size.last_mut().unwrap() += 1;
            } else {
                size.push(1);
            }
        }
        drop(children);
        let nf = size.len();
        let mut of = vec![0u32; n];
        let mut last = Vec::with_capacity(nf);
        let mut c = 0;
        for (s, &w) in size.iter().enumerate() {
            of[c..c + w].fill(s as u32);
            c += w;
            last.push(c - 1);
        }
        let degree: Vec<usize> = last.iter().map(|&j| counts[j] - 1).collect();

        // Relaxation: supernode `s` absorbs `s − 1` (itself possibly grown) when that is its
        // child and the zeros stay within `RELAX`.
        let mut zeros = vec![0usize; nf];
        for s in 1..nf {
            // `s − 1` is a child of `s` when the parent of its last column lies in `s`.
            let p = parent[last[s - 1]];
            if p == NONE || of[p] as usize != s || last[s - 1] + 1 == split {
                continue;
            }
            let (ps, cs) = (size[s], size[s - 1]);
            let (pd, cd) = (degree[s], degree[s - 1]);
            let (pz, cz) = (zeros[s], zeros[s - 1]);
            let new = (ps + pd).saturating_sub(cd) * cs;
            let merged = if new == 0 {
                Some(pz + cz)
            } else {
                let total = new + pz + cz;
                let both = cs + ps;
                let expanded = both * (both + 1) / 2 + pd * both;
                RELAX
                    .iter()
                    .any(|&(most, frac)| most >= both && expanded as f64 * frac >= total as f64)
                    .then_some(total)
            };
            if let Some(z) = merged {
                size[s] += cs;
                size[s - 1] = 0;
                zeros[s] = z;
            }
        }
        drop(zeros);

        // The relaxed supernodes: their columns, patterns' and blocks' offsets.
        let kept: Vec<usize> = (0..nf).filter(|&s| size[s] > 0).collect();
        let ns = kept.len();
        let (mut begin, mut rptr, mut vptr) = (
            Vec::with_capacity(ns + 1),
            Vec::with_capacity(ns + 1),
            Vec::with_capacity(ns + 1),
        );
        let (mut b, mut r, mut v) = (0usize, 0usize, 0usize);
        for &s in &kept {
            begin.push(b);
            rptr.push(r);
            vptr.push(v);
            let (nc, d) = (size[s], degree[s]);
            b += nc;
            r += d;
            v = (nc + d)
                .checked_mul(nc)
                .and_then(|x| x.checked_add(v))
                .ok_or("the factor's size overflows")?;
        }
        begin.push(b);
        rptr.push(r);
        vptr.push(v);
        drop((size, degree, last));
        for (t, w) in begin.windows(2).enumerate() {
            of[w[0]..w[1]].fill(t as u32);
        }
        let up_tree: Vec<usize> = (0..ns)
            .map(|t| match parent[begin[t + 1] - 1] {
                NONE => NONE,
                p => of[p] as usize,
            })
            .collect();

        // Patterns: row `k` appended to every supernode of its row subtree.
        // Fallible: the factor's size is checked against the memory only after this analysis.
        let mut rows = Vec::new();
        rows.try_reserve_exact(r)
            .map_err(|_| "out of memory for the symbolic analysis's patterns")?;
        rows.resize(r, 0usize);
        let mut pos = rptr[..ns].to_vec();
        let mut visited = vec![NONE; ns];
        for k in 0..n {
            let own = of[k] as usize;
            visited[own] = k;
            for &i in upper(k) {
                let mut t = of[i] as usize;
                while visited[t] != k {
                    if pos[t] == rptr[t + 1] {
                        return Err("the symbolic analysis's patterns overflow their counts");
                    }
                    rows[pos[t]] = k;
                    pos[t] += 1;
                    visited[t] = k;
                    t = up_tree[t];
                    if t == NONE {
                        return Err("the symbolic analysis's elimination tree is broken");
                    }
                }
            }
        }
        if pos.iter().zip(&rptr[1..]).any(|(p, e)| p != e) {
            return Err("the symbolic analysis's patterns do not match their counts");
        }
        Ok(Supernodes {
            n,
            begin,
            rptr,
            vptr,
            rows,
        })
    }

    /// The structure as a [`Layout`].
    pub(super) fn layout(&self) -> Layout<'_> {
        let ns = self.begin.len() - 1;
        Layout {
            n: self.n,
            begin: &self.begin[..ns],
            end: &self.begin[1..],
            rptr: &self.rptr,
            vptr: &self.vptr,
            rows: &self.rows,
        }
    }
}

/// The elimination tree (`NONE` at roots) from the strict upper triangle by columns.
fn elimination_tree<'a>(n: usize, upper: impl Fn(usize) -> &'a [usize]) -> Vec<usize> {
    let mut parent = vec![NONE; n];
    let mut ancestor = vec![NONE; n];
    for k in 0..n {
        for &i0 in upper(k) {
            let mut i = i0;
            while i != NONE && i < k {
                let next = ancestor[i];
                ancestor[i] = k;
                if next == NONE {
                    parent[i] = k;
                }
                i = next;
            }
        }
    }
    parent
}

/// A postorder of the forest `parent` (children in ascending order, roots in ascending
/// order).
fn postorder(parent: &[usize]) -> Vec<usize> {
    let n = parent.len();
    let (mut head, mut next) = (vec![NONE; n], vec![NONE; n]);
    for j in (0..n).rev() {
        if parent[j] != NONE {
            next[j] = head[parent[j]];
            head[parent[j]] = j;
        }
    }
    let mut post = Vec::with_capacity(n);
    let mut stack = Vec::new();
    for root in (0..n).filter(|&j| parent[j] == NONE) {
        stack.push(root);
        while let Some(&p) = stack.last() {
            let c = head[p];
            if c == NONE {
                stack.pop();
                post.push(p);
            } else {
                head[p] = next[c];
                stack.push(c);
            }
        }
    }
    post
}

/// `|L_j|` (the diagonal included) for every column, from the lower triangle by columns:
/// row `i`'s subtree has a leaf at `j` when `A_ij ≠ 0` (`i > j`) and `j` is the first
/// such column of its subtree in the postorder; each leaf adds one to its column and
/// takes one off the least common ancestor with the leaf before it, and a column's count is
/// the sum of these over its subtree (Gilbert, Ng and Peyton).
fn column_counts<'a>(
    parent: &[usize],
    post: &[usize],
    lower: impl Fn(usize) -> &'a [usize],
) -> Vec<usize> {
    let n = parent.len();
    // `first[j]`: the postorder position of `j`'s first descendant.
    let mut first = vec![NONE; n];
    let mut delta = vec![0isize; n];
    for (k, &j0) in post.iter().enumerate() {
        let mut j = j0;
        delta[j] = isize::from(first[j] == NONE);
        while j != NONE && first[j] == NONE {
            first[j] = k;
            j = parent[j];
        }
    }
    let (mut max_first, mut prev_leaf) = (vec![NONE; n], vec![NONE; n]);
    let mut ancestor: Vec<usize> = (0..n).collect();
    for &j in post {
        if parent[j] != NONE {
            delta[parent[j]] -= 1;
        }
        for &i in lower(j) {
            if i <= j || (max_first[i] != NONE && first[j] <= max_first[i]) {
                continue;
            }
            max_first[i] = first[j];
            let prev = prev_leaf[i];
            prev_leaf[i] = j;
            delta[j] += 1;
            if prev != NONE {
                // The least common ancestor of the previous leaf and `j`, with path
                // compression.
                let mut q = prev;
                while q != ancestor[q] {
                    q = ancestor[q];
                }
                let mut s = prev;
                while s != q {
                    let up = ancestor[s];
                    ancestor[s] = q;
                    s = up;
                }
                delta[q] -= 1;
            }
        }
        if parent[j] != NONE {
            ancestor[j] = parent[j];
        }
    }
    for j in 0..n {
        if parent[j] != NONE {
            delta[parent[j]] += delta[j];
        }
    }
    delta.into_iter().map(|d| d as usize).collect()
}
