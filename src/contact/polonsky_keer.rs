//! Polonsky–Keer constrained conjugate gradients (Polonsky & Keer, *Wear* 231 (1999) 206–219),
//! matrix-free with the FFT influence operator.
//!
//! # Problem
//!
//! With heights `h` (row-major `ny × nx`), `u = C p` and the conventions of `docs/conventions.md`, find
//!
//! ```text
//! p ≥ 0,   g = max h − Δ − h + C p ≥ 0,   p·g = 0,
//! ```
//!
//! i.e. minimise `f(p) = ½ pᵀCp − bᵀp` over `p ≥ 0` with `b_i = Δ − (max h − h_i)`; the
//! gradient of `f` is `∇f = Cp − b = g`. Two controls:
//!
//! * **displacement** ([`Control::Approach`]): `Δ ≥ 0` is given and fixed. There is no
//!   mean-gap adjustment: the rigid-body term `max h − Δ` is part of the data.
//! * **load** ([`Control::MeanPressure`]): `p̄ > 0` is given; every iterate keeps
//!   `Σ p = p̄·N` (total force `F = p̄·A0 = dx² Σ p`). `Δ` is an unknown: each evaluation of
//!   the gap takes it from the mean over the contact set `I_c = {p > 0}`,
//!
//!   ```text
//!   Δ = mean_{i ∈ I_c} (max h − h_i + u_i),
//!   ```
//!
//!   so that `g = max h − Δ − h + u` has zero mean on `I_c` (the paper's `g ← g − ḡ`).
//!   Positive `Δ` means the flat has moved down into the surface from first touch. With
//!   `boundary = "periodic"` it is measured in that convention (u has zero mean, `docs/conventions.md`),
//!   and it is reported as computed, not clamped.
//!
//! # Iteration (the paper's steps, in this sign convention)
//!
//! ```text
//! 1. g = max h − Δ − h + u                          (load: Δ from the mean over I_c)
//!    G = Σ_{I_c} g²
//! 2. t_i = g_i + δ (G / G_old) t_i on I_c, 0 elsewhere;  G_old = G
//! 3. r = C t;  (load: r ← r − mean_{I_c} r)
//! 4. τ = Σ_{I_c} g t / Σ_{I_c} r t
//! 5. p_i ← p_i − τ t_i on I_c;  p_i < 0 → p_i = 0
//! 6. I_ol = {p_i = 0, g_i < 0}:  empty → δ = 1;  else δ = 0 and p_i ← −τ g_i on I_ol
//! 7. load: p ← p · (p̄N / Σ p)
//! ```
//!
//! `I_ol` is taken after the truncation of step 5, with the gap of step 1, exactly as in the
//! paper (a point truncated in this step that still overlaps re-enters at once); truncation
//! alone does not reset `δ`, only a non-empty `I_ol` does.
//!
//! Two additions, both outside the paper's normal path:
//!
//! * **Empty or stalled contact set.** When `I_c` is empty (a displacement-controlled cold
//!   start from `p = 0`) or the conjugate direction carries no descent (`Σ g t ≤ 0`, possible
//!   only after truncation without reset), the step is a projected steepest-descent step on
//!   `W = I_c ∪ {p = 0, g < 0}`: `t = g` on `W`, `δ = 0`, same exact line search. From `p = 0`
//!   this is the exact line search along the penetration, `p = τ·max(−g, 0)`, which then
//!   builds up the contact set. (Measured on self-affine surfaces, 257²–1025², Δ = 0.1–0.6 h_s:
//!   starting instead from the Winkler guess `max(−g, 0)/C_00`, or a quarter of it, changes
//!   the iteration count by less than ±10 %, either way; so the cold start stays `p = 0`.)
//! * **Flat direction.** With the periodic operator a constant field has zero stiffness; if
//!   `tᵀCt ≤ 0` the step is the largest one keeping `p ≥ 0` (ratio test).
//!
//! # One operator application per iteration
//!
//! The paper needs `C p` (step 1) and `C t` (step 3) each iteration. Here step 1 is
//! incremental. Write the new pressure as the linear step plus a correction,
//! `p' = p − τ t + d`, where `d` is non-zero only at the points truncated in step 5 or entering
//! through `I_ol` in step 6. Then
//!
//! ```text
//! displacement control:  g' = g − τ r + C d          (u is not needed while iterating)
//! load control:          u' = s (u − τ r + C d),  p' ← s p',  s = p̄N / Σ p'
//! ```
//!
//! * `d = 0` (the set did not change): nothing more; the iteration costs one FFT product.
//! * `1 ≤ |supp d| ≤` [`sparse_limit`]: `C d` by direct summation with the influence table
//!   `C e_0`, `N` multiply-adds per point. The table is the kernel table when one is at hand
//!   (free solves built here: the Love table the operator is made from; a caller's
//!   [`solve_with_kernel`]), otherwise it is built once by one product.
//! * more changes: a fresh product `u = C p`, a second product in that iteration — unless the
//!   changes are wholesale, see below.
//!
//! # Chord steps (displacement control)
//!
//! After a coarse start, or from `p = 0`, the first tens of iterations truncate or add
//! thousands of points each (at 2049², Δ = 0.3 h_s, 15–45 % of the contact set in each of the
//! first 20 iterations), so each would cost two products. When the last iteration changed
//! more than [`CHORD_FRACTION`] of the contact set (and more than [`sparse_limit`] points),
//! the next one is a chord step instead, with `β = 0`:
//!
//! ```text
//! d = P(p − τ₀ t) − p        P = steps 5–6 (truncation, I_ol entry), τ₀ = last step length
//! r = C d                    the one product of the iteration
//! s = min(1, −Σ g d / Σ d r) exact minimiser of f on the chord p + s d, 0 < s ≤ 1
//! p ← p + s d,  g ← g + s r
//! ```
//!
//! The new `p` lies on the segment between `p ≥ 0` and `P(p − τ₀ t) ≥ 0`, so it is feasible,
//! and the gap is updated exactly by the product of the whole change. `Σ g d < 0` (a descent
//! chord) is required, otherwise the iteration takes the regular step. `τ₀` starts from the
//! last line-search length and is scaled by `s` (or by 1.5 when `s = 1`) after each chord
//! step. Once the changes fall below the threshold the regular conjugate iteration resumes.
//! A chord step is a projected steepest-descent step, so it converges more slowly than the
//! conjugate iteration; it pays only while the contact set changes wholesale, where the
//! regular iteration restarts (`δ = 0`) anyway. Load control keeps the regular steps (its
//! step 7 rescales `p`, which the chord does not model).
//!
//! Measured at 4097² (RMD D = 2.1, free, Δ = 0.1/0.3/0.6 h_s, tol 1e-8, coarse start, 2
//! cores): 56/132/202 fine iterations of which 34/69/117 chord steps, 64/167/260 fine
//! products (without chord steps 43/118/177 iterations, 72/202/321 products); the whole
//! solve 31.0/85.7/138.3 s (32.6/93.4/158.2 s), 1.28/1.33/1.45 (1.69/1.73/1.89) times one
//! operator application per fine iteration. With the FFT grid padded to 8192 instead of
//! 8640 (`crate::grid::padded`): 56/133/197 iterations, 64/169/249 fine products,
//! 28.4/76.1/117.2 s, 1.22/1.34/1.45 times one application.
//!
//! The iterates `t`, `z` and `p` vanish off the contact set, often on whole rows of the grid;
//! the operator skips the forward row FFTs of zero rows (their transform is zero), so a
//! product of such a field costs less than one of a dense field.
//!
//! Before the solver declares convergence on an incrementally updated state it recomputes
//! `u = C p` and the gap and tests again, so the returned fields and certificate always come
//! from a fresh product (round-off drift of the increments cannot fake convergence).
//!
//! # Preconditioning
//!
//! With [`Options::precondition`] (the default) a conjugate step on a stable contact set uses
//! the preconditioned residual `z = M g` on `I_c`, `M` the inverse half-space compliance
//! `E*|q|/2` applied by FFT on the `ny × nx` grid zero-padded to a 2,3,5-smooth size
//! ([`Operator::inverse_compliance`]; `q = 0` gets the stiffness of the longest wavelength):
//!
//! ```text
//! z = M (g on I_c) on I_c,   G = Σ_{I_c} g z,   t = z + δ (G / G_old) t
//! ```
//!
//! (preconditioned CG on `C_PP`, in the spirit of Vollebregt's FFT-preconditioned BCCG). `M`
//! is SPD on the padded grid, so its restriction to `I_c` is SPD and the step is a descent
//! step; the exact line search is unchanged. A preconditioned `τ` is dimensionless, so points
//! entering through `I_ol` in such a step get `p = −τ g / C_00` (the pressure that closes the
//! gap of that point alone) instead of `−τ g`. A steepest-descent step, or a conjugate step
//! after one, stays plain, and so does every step while more than half the points are in
//! contact (where preconditioning stops paying); it is switched off for the rest of a solve
//! when the certificate grows past `10³×` its best value. Each preconditioned iteration costs one more FFT pair on the
//! unpadded grid (about a quarter of a free-boundary product; rows without a contact point
//! skip both their forward and their inverse row FFT, as `z` is only used on `I_c`); measured at 257², tol 1e-12,
//! it takes 1.2–2.8× fewer iterations (see [`PRECONDITION_MAX_FRACTION`]); the answer is
//! the same minimiser (identical contact sets in every test).
//!
//! # Convergence
//!
//! The KKT certificate, relative to the height range `h_s = max h − min h`:
//!
//! ```text
//! kkt = max( −min_i g_i,  max_{i ∈ I_c} |g_i|,  Σ p_i |g_i| / Σ p_i ) / h_s
//! ```
//!
//! (the last term is dropped when `Σ p = 0`; the scale is `max(h_s, Δ)` in displacement
//! control and `max(h_s, |Δ|, p̄ · C_00)` in load control, with the current `Δ`,
//! `C_00 = 4 dx ln(1+√2)/(π E*)`; they differ from `h_s` only past the height range, where
//! `u` and `Δ` are many `h_s` and round-off is relative to them). The solver stops when
//! `kkt ≤ tol`, default [`DEFAULT_TOL`] `= 1e-12`: reachable in double precision (round-off
//! of `u` is `~1e-15 · max |u|`) at a few CG iterations per decade. For a flat surface
//! (`h_s = 0`) the scale is `Δ` (displacement control) or `p̄ · C_00` (load control).
//!
//! # Determinism
//!
//! Every reduction sums fixed chunks of [`CHUNK`] points in index order and combines the
//! partial results sequentially in chunk order, and the operator is deterministic, so results
//! do not depend on the number of rayon threads.

use std::borrow::Cow;
use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::capped;
use super::multilevel::{self, CoarseCost};
use crate::alloc;
use crate::elastic::kernel::{love_displacement, Kernel};
use crate::elastic::memory;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::{check_shape, Boundary};

/// Default KKT tolerance, relative to the height range.
pub const DEFAULT_TOL: f64 = 1e-12;

/// Points per reduction chunk: fixed, so the summation order is independent of the thread count.
pub const CHUNK: usize = 4096;

/// Non-linear pressure changes of one iteration (truncations, `I_ol`) up to this many are
/// applied to the gap by direct summation with the influence table, `N` multiply-adds each,
/// instead of a fresh FFT product `C p`. Measured at 1025² and 2049² (2 cores): one point
/// costs about 1/50 of a free-boundary product; the periodic product is about 4× cheaper (no
/// padding). See [`sparse_limit`].
pub const SPARSE_MAX: usize = 40;

/// The direct-summation limit for a boundary: [`SPARSE_MAX`] (free) or a quarter of it
/// (periodic).
pub fn sparse_limit(boundary: Boundary) -> usize {
    match boundary {
        Boundary::Free => SPARSE_MAX,
        Boundary::Periodic => SPARSE_MAX / 4,
    }
}

/// Preconditioned steps are taken while at most this fraction of the points is in contact.
/// Measured on RMD (D = 2.1, 2.5) and spectral (H = 0.5, 0.9) surfaces at 257², tol 1e-12,
/// iterations summed over 8 surfaces, plain → preconditioned: free Δ = 0.3/0.7/1.0/1.5/2.0 h_s
/// 573 → 333, 884 → 478, 1090 → 670, 1268 → 797, 1382 → 1131; periodic at 0.5/0.8/0.9/0.95
/// of full contact 611 → 306, 1470 → 525, 1999 → 952, 2213 → 1250, and unchanged near full
/// contact (0.999), where more than half of the points are in contact for most of the solve.
pub const PRECONDITION_MAX_FRACTION: f64 = 0.5;

/// A preconditioned solve whose certificate grows past this multiple of its best value so
/// far continues with plain Polonsky–Keer steps.
const SAFEGUARD: f64 = 1e3;

/// Chord steps replace the regular step while an iteration changes more than this fraction
/// of the contact set (and more than the direct-summation limit) by truncation or `I_ol`
/// entry. Measured at 2049² (RMD D = 2.1, free, Δ = 0.1/0.3/0.6 h_s, coarse start, tol
/// 1e-8): without chord steps 52/130/212 fine products in 34/78/122 iterations; with
/// 0.3 % 47/113/177 in 42/99/156; 0.5 % 47/122/156 in 42/102/124; 1 % 45/106/154 in
/// 39/83/112; 3 % 41/118/161 in 36/88/109. A lower fraction means fewer products per
/// iteration but more (steepest-descent) iterations; 0.5 % keeps the whole solve time within
/// a few per cent of the best of these.
pub const CHORD_FRACTION: f64 = 0.005;

/// The chord's trial length `τ₀` grows by this factor after a step that used the whole chord
/// (`s = 1`) and shrinks to `max(s, CHORD_SHRINK_MIN) τ₀` otherwise.
const CHORD_GROW: f64 = 1.5;
const CHORD_SHRINK_MIN: f64 = 0.1;

/// Whether `changed` truncations and `I_ol` entries out of `n_c` contact points make the
/// next step a chord step.
fn wholesale(changed: usize, n_c: usize, sparse_max: usize) -> bool {
    changed > sparse_max && changed as f64 > CHORD_FRACTION * n_c as f64
}

/// `should_stop` is polled at least every this many iterations…
const STOP_EVERY: usize = 10;
/// …and at least this often on grids where ten iterations take long.
const STOP_INTERVAL: Duration = Duration::from_millis(250);

/// What is imposed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Control {
    /// The approach `Δ ≥ 0` of the flat below the highest point.
    Approach(f64),
    /// The mean pressure `p̄ > 0` (`F = p̄·A0`); the approach is an output.
    MeanPressure(f64),
}

/// The surface and the elastic model.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a> {
    /// Row-major `ny × nx` heights.
    pub heights: &'a [f64],
    pub ny: usize,
    pub nx: usize,
    /// Grid spacing (both axes).
    pub dx: f64,
    /// Contact modulus `E* = E/(1 − ν²)`.
    pub e_star: f64,
    pub boundary: Boundary,
}

/// Solver settings.
#[derive(Clone, Copy)]
pub struct Options<'a> {
    /// Stop when the KKT certificate (relative to `h_s`) is `≤ tol`.
    pub tol: f64,
    /// Iteration cap; `None` → [`default_max_iter`].
    pub max_iter: Option<usize>,
    /// Warm start: a pressure field (`ny × nx`, finite; negative values are clipped to 0).
    /// In load control it is rescaled to the imposed load.
    pub initial_pressure: Option<&'a [f64]>,
    /// Refuse up front with [`Error::TooLarge`] when [`memory::polonsky_keer`] exceeds this (bytes).
    pub memory_limit: Option<u64>,
    /// Polled every ~10 iterations (and at least every 0.25 s); `true` → [`Error::Interrupted`].
    pub should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
    /// Precondition the conjugate directions with the periodic inverse compliance
    /// `E*|q|/2` restricted to the contact set (see the module documentation).
    pub precondition: bool,
    /// Start a cold solve from the solution on the grid coarsened by two, recursively
    /// ([`crate::multilevel`]); ignored with a warm start and on grids smaller than
    /// [`crate::multilevel::COARSE_START_MIN_SIDE`] per side.
    pub coarse_start: bool,
    /// Take chord steps while the contact set changes wholesale (displacement control, see
    /// the module documentation); `false` keeps every iteration a regular Polonsky–Keer step.
    pub chord_steps: bool,
    /// Hardness `H`: cap the pressure at `p ≤ H` (elastic–perfectly-plastic contact, solved by
    /// [`crate::contact::capped`]). `None` or `+∞`: the elastic problem, by this module's
    /// iteration unchanged.
    pub hardness: Option<f64>,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Options {
            tol: DEFAULT_TOL,
            max_iter: None,
            initial_pressure: None,
            memory_limit: None,
            should_stop: None,
            precondition: true,
            coarse_start: true,
            chord_steps: true,
            hardness: None,
        }
    }
}

/// A converged contact state.
#[derive(Clone, Debug)]
pub struct Solution {
    pub ny: usize,
    pub nx: usize,
    /// Pressure `p ≥ 0`, row-major.
    pub pressure: Vec<f64>,
    /// Displacement `u = C p` (fresh product of the returned `p`).
    pub displacement: Vec<f64>,
    /// Gap `g = max h − Δ − h + u`, not clamped: contact points carry the residual `|g| ≤ kkt·h_s`.
    pub gap: Vec<f64>,
    /// Approach `Δ` (the imposed one, or the computed one in load control).
    pub approach: f64,
    /// Conjugate-gradient iterations (each one product `C t`).
    pub iterations: usize,
    /// FFT operator applications in total: one per iteration, plus fresh products `C p` (start,
    /// large set changes, convergence checks) and one for the influence table when no kernel
    /// table was at hand (periodic [`solve`], [`solve_with_operator`]).
    pub applies: usize,
    /// Preconditioner applications (FFT pairs on the unpadded `ny × nx` grid), one per
    /// preconditioned iteration.
    pub preconditioner_applies: usize,
    /// Iterations that were chord steps (included in `iterations`; each one product `C d`).
    pub chord_steps: usize,
    /// KKT certificate relative to `h_s` (see the module documentation).
    pub kkt: f64,
    /// Number of points with `p > 0`.
    pub contact_points: usize,
    /// Number of points at the hardness, `p = H` (0 without a hardness).
    pub plastic_points: usize,
    /// Total force `F = dx² Σ p`.
    pub load: f64,
    /// Mean pressure `p̄ = Σ p / N`.
    pub mean_pressure: f64,
    /// What the coarse levels of a coarse start cost (zero without one); not included in
    /// `iterations`, `applies`, `preconditioner_applies`.
    pub coarse: CoarseCost,
}

/// Default iteration cap, `max(5000, ⌈100·N^¼⌉)`. CG iterations grow like `√cond(C)`, and
/// `cond(C) = O(√N)`: measured on self-affine surfaces (H = 0.9, free, Δ = 0.3 h_s, tol 1e-10)
/// 52, 89, 112 and 152 iterations at 129², 513², 1025² and 2049², so the cap leaves a margin
/// of about 30× for harder cases (large contact fractions, periodic near full contact).
pub fn default_max_iter(n: usize) -> usize {
    let q = (100.0 * (n as f64).sqrt().sqrt()).ceil() as usize;
    q.max(5000)
}

/// Solve on a new operator built for `problem` (free: Love kernel, zero-padded FFT; periodic:
/// spectral stiffness).
pub fn solve(problem: &Problem, control: Control, opts: &Options) -> Result<Solution> {
    solve_level(
        problem,
        control,
        opts,
        Finish::Confirmed,
        multilevel::MAX_COARSE_LEVELS,
    )
}

/// How a solve ends once the certificate on the incrementally updated state meets `tol`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Finish {
    /// Recompute `u = C p` and test again: the returned fields and certificate come from a
    /// fresh product (every solve a caller sees).
    Confirmed,
    /// Stop there (a coarse level of a coarse start, whose pressure is only a starting point).
    /// The returned displacement is empty unless the last state came from a fresh product.
    Incremental,
}

/// [`solve`] ending as `finish` says, with at most `levels` coarse levels below it.
pub(crate) fn solve_level(
    problem: &Problem,
    control: Control,
    opts: &Options,
    finish: Finish,
    levels: usize,
) -> Result<Solution> {
    validate(problem, control, opts)?;
    let (ny, nx) = (problem.ny, problem.nx);
    if capped::finite_hardness(opts).is_some() {
        check_memory(problem, opts)?;
        return capped::solve_level(problem, control, opts, levels);
    }
    if let Some(limit) = opts.memory_limit {
        let bytes = memory::polonsky_keer(ny, nx, problem.boundary);
        if bytes > limit {
            return Err(Error::TooLarge {
                bytes,
                limit,
                what: format!(
                    "Polonsky–Keer on a {ny} × {nx} {} grid",
                    boundary_name(problem.boundary)
                ),
            });
        }
    }
    // The coarse levels run before the fine operator exists, so their memory is not added
    // to its.
    let start = coarse_start(problem, control, opts, levels)?;
    match problem.boundary {
        Boundary::Free => {
            // The Love kernel table is the influence table `C e_0` of the sparse corrections:
            // kept instead of being rebuilt by a product.
            let kernel = Kernel::try_new(ny, nx, problem.dx, problem.e_star)?;
            let op = Operator::try_free(&kernel)?;
            run_from(
                &op,
                Some(&kernel.table),
                problem,
                control,
                opts,
                start,
                finish,
            )
        }
        Boundary::Periodic => {
            let op = Operator::try_periodic(ny, nx, problem.dx, problem.e_star)?;
            run_from(&op, None, problem, control, opts, start, finish)
        }
    }
}

/// The coarse-level start of a cold solve, if [`Options::coarse_start`] asks for one.
fn coarse_start(
    problem: &Problem,
    control: Control,
    opts: &Options,
    levels: usize,
) -> Result<Option<(Vec<f64>, CoarseCost)>> {
    if levels > 0 && multilevel::applies_to(problem.ny, problem.nx, opts) {
        multilevel::start(problem, control, opts, levels)
    } else {
        Ok(None)
    }
}

/// [`run`] from a coarse start (if any), reporting its cost.
fn run_from(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    start: Option<(Vec<f64>, CoarseCost)>,
    finish: Finish,
) -> Result<Solution> {
    match start {
        Some((p0, cost)) => {
            // The start pressure becomes the iterate (no second N-vector).
            let mut sol = run(op, table, problem, control, opts, Some(p0), finish)?;
            sol.coarse = cost;
            Ok(sol)
        }
        None => run(op, table, problem, control, opts, None, finish),
    }
}

/// Solve with an operator built by the caller (e.g. reused over a sweep of approaches). The
/// operator must be the one of `problem` (shape and boundary are checked; `dx` and `E*` are
/// trusted).
pub fn solve_with_operator(
    op: &Operator,
    problem: &Problem,
    control: Control,
    opts: &Options,
) -> Result<Solution> {
    solve_with_kernel(op, None, problem, control, opts)
}

/// [`solve_with_operator`] with the caller's influence table `C e_0` (row-major `ny × nx`,
/// the [`Kernel`] table of `op`: the Love table for the free boundary, the circulant's first
/// column for the periodic one), which spares the product that would build it.
pub fn solve_with_kernel(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
) -> Result<Solution> {
    validate(problem, control, opts)?;
    if let Some(t) = table {
        if t.len() != problem.ny * problem.nx {
            return Err(Error::invalid(
                "kernel",
                format!(
                    "{} values for a {} × {} grid",
                    t.len(),
                    problem.ny,
                    problem.nx
                ),
            ));
        }
    }
    if op.ny != problem.ny || op.nx != problem.nx || op.boundary != problem.boundary {
        return Err(Error::invalid(
            "operator",
            format!(
                "built for a {} × {} {} grid, the heights are {} × {} {}",
                op.ny,
                op.nx,
                boundary_name(op.boundary),
                problem.ny,
                problem.nx,
                boundary_name(problem.boundary)
            ),
        ));
    }
    if capped::finite_hardness(opts).is_some() {
        return capped::solve_with_operator(
            op,
            table,
            problem,
            control,
            opts,
            multilevel::MAX_COARSE_LEVELS,
        );
    }
    let start = coarse_start(problem, control, opts, multilevel::MAX_COARSE_LEVELS)?;
    run_from(op, table, problem, control, opts, start, Finish::Confirmed)
}

/// [`Error::TooLarge`] when [`memory::polonsky_keer`] exceeds the options' memory limit.
fn check_memory(problem: &Problem, opts: &Options) -> Result<()> {
    let (ny, nx) = (problem.ny, problem.nx);
    if let Some(limit) = opts.memory_limit {
        let bytes = memory::polonsky_keer(ny, nx, problem.boundary);
        if bytes > limit {
            return Err(Error::TooLarge {
                bytes,
                limit,
                what: format!(
                    "Polonsky–Keer on a {ny} × {nx} {} grid",
                    boundary_name(problem.boundary)
                ),
            });
        }
    }
    Ok(())
}

fn boundary_name(b: Boundary) -> &'static str {
    match b {
        Boundary::Free => "free",
        Boundary::Periodic => "periodic",
    }
}

fn validate(problem: &Problem, control: Control, opts: &Options) -> Result<()> {
    let (ny, nx) = (problem.ny, problem.nx);
    check_shape(ny, nx)?;
    let n = ny
        .checked_mul(nx)
        .ok_or_else(|| Error::invalid("heights", "the grid is too large"))?;
    if problem.heights.len() != n {
        return Err(Error::invalid(
            "heights",
            format!(
                "expected {ny} × {nx} = {n} values, got {}",
                problem.heights.len()
            ),
        ));
    }
    if !(problem.dx.is_finite() && problem.dx > 0.0) {
        return Err(Error::invalid(
            "dx",
            format!("must be a positive finite number, got {}", problem.dx),
        ));
    }
    if !(problem.e_star.is_finite() && problem.e_star > 0.0) {
        return Err(Error::invalid(
            "e_star",
            format!("must be a positive finite number, got {}", problem.e_star),
        ));
    }
    match control {
        Control::Approach(d) if !(d.is_finite() && d >= 0.0) => {
            return Err(Error::invalid(
                "approach",
                format!("must be a finite number ≥ 0, got {d}"),
            ));
        }
        Control::MeanPressure(m) if !(m.is_finite() && m > 0.0) => {
            return Err(Error::invalid(
                "mean_pressure",
                format!("must be a positive finite number, got {m}"),
            ));
        }
        _ => {}
    }
    if let Some(cap) = opts.hardness {
        capped::check_hardness(cap)?;
        if let Control::MeanPressure(m) = control {
            if m > cap {
                return Err(Error::invalid(
                    "mean_pressure",
                    format!(
                        "{m} exceeds the hardness {cap}: a perfectly plastic surface carries \
                         at most p̄ = hardness (every point at the hardness)"
                    ),
                ));
            }
        }
    }
    if !(opts.tol.is_finite() && opts.tol > 0.0) {
        return Err(Error::invalid(
            "tol",
            format!("must be a positive finite number, got {}", opts.tol),
        ));
    }
    if let Some(i) = first_non_finite(problem.heights) {
        return Err(Error::invalid(
            "heights",
            format!(
                "must be finite; element ({}, {}) is {}",
                i / nx,
                i % nx,
                problem.heights[i]
            ),
        ));
    }
    if let Some(p0) = opts.initial_pressure {
        if p0.len() != n {
            return Err(Error::invalid(
                "initial_pressure",
                format!(
                    "must have the shape of the heights ({ny} × {nx}), got {} values",
                    p0.len()
                ),
            ));
        }
        if let Some(i) = first_non_finite(p0) {
            return Err(Error::invalid(
                "initial_pressure",
                format!(
                    "must be finite; element ({}, {}) is {}",
                    i / nx,
                    i % nx,
                    p0[i]
                ),
            ));
        }
    }
    Ok(())
}

fn first_non_finite(v: &[f64]) -> Option<usize> {
    v.par_iter().position_first(|x| !x.is_finite())
}

/// Partial results of one fused pass over a chunk; combined in chunk order.
#[derive(Clone, Copy, Debug)]
struct Acc {
    /// Points with `p > 0`.
    n_c: usize,
    /// Σ p.
    sum_p: f64,
    /// Σ p |g|.
    sum_pg: f64,
    /// Σ_{I_c} g².
    gg: f64,
    /// min g over all points.
    min_g: f64,
    /// max |g| over `I_c`.
    max_gc: f64,
    /// Non-finite gaps seen (overflow guard).
    bad: usize,
    /// Σ g t (direction pass).
    gt: f64,
    /// Σ_W t (direction pass).
    st: f64,
    /// Points of the working set (direction pass).
    n_w: usize,
    /// Σ r t (curvature pass).
    rt: f64,
    /// Σ_W r (curvature pass).
    rw: f64,
    /// Σ_{I_c} (max h − h), Σ_{I_c} u (load control: the approach).
    sh: f64,
    su: f64,
    /// Points clamped to zero / entering through `I_ol` in the update pass.
    n_trunc: usize,
    n_ol: usize,
    /// Points whose new pressure differs from the linear step `p − τ t` (truncated or in
    /// `I_ol`): the support of the correction `d`.
    n_nl: usize,
}

impl Acc {
    const ZERO: Acc = Acc {
        n_c: 0,
        sum_p: 0.0,
        sum_pg: 0.0,
        gg: 0.0,
        min_g: f64::INFINITY,
        max_gc: 0.0,
        bad: 0,
        gt: 0.0,
        st: 0.0,
        n_w: 0,
        rt: 0.0,
        rw: 0.0,
        sh: 0.0,
        su: 0.0,
        n_trunc: 0,
        n_ol: 0,
        n_nl: 0,
    };

    fn merge(self, o: &Acc) -> Acc {
        Acc {
            n_c: self.n_c + o.n_c,
            sum_p: self.sum_p + o.sum_p,
            sum_pg: self.sum_pg + o.sum_pg,
            gg: self.gg + o.gg,
            min_g: self.min_g.min(o.min_g),
            max_gc: self.max_gc.max(o.max_gc),
            bad: self.bad + o.bad,
            gt: self.gt + o.gt,
            st: self.st + o.st,
            n_w: self.n_w + o.n_w,
            rt: self.rt + o.rt,
            rw: self.rw + o.rw,
            sh: self.sh + o.sh,
            su: self.su + o.su,
            n_trunc: self.n_trunc + o.n_trunc,
            n_ol: self.n_ol + o.n_ol,
            n_nl: self.n_nl + o.n_nl,
        }
    }

    /// Account one point's pressure and gap for the certificate and `G`.
    #[inline(always)]
    fn observe(&mut self, p: f64, g: f64) {
        if g < self.min_g {
            self.min_g = g;
        }
        if !g.is_finite() {
            self.bad += 1;
        }
        if p > 0.0 {
            let ag = g.abs();
            self.n_c += 1;
            self.sum_p += p;
            self.sum_pg += p * ag;
            self.gg += g * g;
            if ag > self.max_gc {
                self.max_gc = ag;
            }
        }
    }

    /// Unscaled `max(−min g, max_{I_c} |g|, Σ p|g| / Σ p)`.
    fn certificate(&self) -> f64 {
        if self.bad > 0 {
            return f64::NAN;
        }
        let mut c = (-self.min_g).max(self.max_gc).max(0.0);
        if self.sum_p > 0.0 {
            c = c.max(self.sum_pg / self.sum_p);
        }
        c
    }
}

/// Arrays and scratch of one solve. All `N`-vectors are allocated once.
///
/// Displacement control iterates on the gap alone (`g ← g − τ r` is the whole effect of a
/// linear step), so `u` is only needed right after a fresh product: it is written into `r`,
/// which is scratch at that point, and `u` stays empty. Load control keeps `u` because step 7
/// scales it with `p`.
struct Work<'a> {
    op: &'a Operator,
    h: &'a [f64],
    hmax: f64,
    p: Vec<f64>,
    u: Vec<f64>,
    g: Vec<f64>,
    t: Vec<f64>,
    r: Vec<f64>,
    /// `u` lives in `r` (displacement control).
    u_in_r: bool,
    /// Influence of a unit pressure at point 0, `C e_0` (row-major `ny × nx`): the caller's
    /// kernel table, or built on first use by one product: free,
    /// `C_{ab} = table[|Δi|, |Δj|]`; periodic, `table[Δi mod ny, Δj mod nx]`.
    table: Cow<'a, [f64]>,
    /// Per chunk, up to [`SPARSE_MAX`] `(index, d)` of the last update's non-linear changes.
    slots: Vec<(usize, f64)>,
    /// Scratch list of all changes in index order.
    changes: Vec<(usize, f64)>,
    ny: usize,
    nx: usize,
    periodic: bool,
    parts: Vec<Acc>,
    applies: usize,
    /// Preconditioner (periodic inverse compliance on the `ny × nx` grid), its diagonal, the
    /// preconditioned residual `z = M g` on `I_c`, and the number of its applications.
    pre: Option<Operator>,
    z: Vec<f64>,
    pre_applies: usize,
}

fn combine(parts: &[Acc]) -> Acc {
    parts.iter().fold(Acc::ZERO, |a, b| a.merge(b))
}

/// `t_k ← f(k, p_k, g_k, t_k, acc)` over the fixed chunks, each chunk's reductions in its
/// `acc`; returns them combined. The passes that rewrite `t` (the directions, the chord trial).
fn rewrite_t(
    parts: &mut [Acc],
    t: &mut [f64],
    p: &[f64],
    g: &[f64],
    f: impl Fn(usize, f64, f64, f64, &mut Acc) -> f64 + Sync,
) -> Acc {
    parts
        .par_iter_mut()
        .zip(t.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(c, (acc, tc))| {
            let lo = c * CHUNK;
            let (pc, gc) = (&p[lo..lo + tc.len()], &g[lo..lo + tc.len()]);
            let mut a = Acc::ZERO;
            for (i, ti) in tc.iter_mut().enumerate() {
                *ti = f(lo + i, pc[i], gc[i], *ti, &mut a);
            }
            *acc = a;
        });
    combine(parts)
}

impl Work<'_> {
    /// `u = C p`.
    fn refresh_u(&mut self) {
        let u = if self.u_in_r {
            &mut self.r
        } else {
            &mut self.u
        };
        self.op.apply(&self.p, u);
        self.applies += 1;
    }

    /// The displacement field of the last fresh product.
    fn into_displacement(self) -> Vec<f64> {
        if self.u_in_r {
            self.r
        } else {
            self.u
        }
    }

    /// `p ← s p`.
    fn scale_p(&mut self, s: f64) {
        self.p.par_iter_mut().for_each(|v| *v *= s);
    }

    /// `g = (max h − Δ) − h + u`, optionally scaling `p` and `u` by `s` first (load control,
    /// step 7 folded into the next gap evaluation); reductions for the certificate and `G`.
    fn gap_pass(&mut self, delta: f64, s: Option<f64>) -> Acc {
        let top = self.hmax - delta;
        let h = self.h;
        let Work {
            p,
            u,
            g,
            r,
            u_in_r,
            parts,
            ..
        } = self;
        let u = if *u_in_r { r } else { u };
        parts
            .par_iter_mut()
            .zip(g.par_chunks_mut(CHUNK))
            .zip(p.par_chunks_mut(CHUNK))
            .zip(u.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (((acc, gc), pc), uc))| {
                let hc = &h[c * CHUNK..c * CHUNK + gc.len()];
                let mut a = Acc::ZERO;
                match s {
                    Some(s) => {
                        for i in 0..gc.len() {
                            pc[i] *= s;
                            uc[i] *= s;
                            let gi = top - hc[i] + uc[i];
                            gc[i] = gi;
                            a.observe(pc[i], gi);
                        }
                    }
                    None => {
                        for i in 0..gc.len() {
                            let gi = top - hc[i] + uc[i];
                            gc[i] = gi;
                            a.observe(pc[i], gi);
                        }
                    }
                }
                *acc = a;
            });
        combine(parts)
    }

    /// Load control: `Σ_{I_c} (max h − h)`, `Σ_{I_c} u`, `|I_c|`, `Σ p` of the current state.
    fn contact_sums(&mut self) -> Acc {
        let (h, u, p, hmax) = (self.h, &self.u, &self.p, self.hmax);
        self.parts.par_iter_mut().enumerate().for_each(|(c, acc)| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(h.len());
            let mut a = Acc::ZERO;
            for i in lo..hi {
                if p[i] > 0.0 {
                    a.n_c += 1;
                    a.sum_p += p[i];
                    a.sh += hmax - h[i];
                    a.su += u[i];
                }
            }
            *acc = a;
        });
        combine(&self.parts)
    }

    /// Step 1 from a fresh `u`: the gap (load control: with `Δ` from the mean over `I_c`).
    /// Returns the reductions and the approach.
    fn evaluate(&mut self, mode: Mode) -> (Acc, f64) {
        match mode {
            Mode::Displacement(delta) => (self.gap_pass(delta, None), delta),
            Mode::Load(_) => {
                let a = self.contact_sums();
                let delta = if a.n_c > 0 {
                    (a.sh + a.su) / a.n_c as f64
                } else {
                    0.0
                };
                (self.gap_pass(delta, None), delta)
            }
        }
    }

    /// Preconditioned residual `z = M (g on I_c)` restricted to `I_c`; returns `Σ_{I_c} g z`
    /// (in `gt`). `r` is scratch here (between an update and the next product `C t`).
    fn precondition(&mut self) -> Acc {
        let Work { p, g, z, r, .. } = self;
        z.par_chunks_mut(CHUNK)
            .zip(p.par_chunks(CHUNK))
            .zip(g.par_chunks(CHUNK))
            .for_each(|((zc, pc), gc)| {
                for i in 0..zc.len() {
                    zc[i] = if pc[i] > 0.0 { gc[i] } else { 0.0 };
                }
            });
        // z is only needed on I_c: rows without a contact point skip their inverse row FFT.
        let nx = self.nx;
        let in_contact = |i: usize| p[i * nx..(i + 1) * nx].iter().any(|&v| v > 0.0);
        self.pre
            .as_ref()
            .expect("precondition() needs a preconditioner")
            .apply_on_rows(z, r, &in_contact);
        self.pre_applies += 1;
        let (p, g, r) = (&self.p, &self.g, &self.r);
        self.parts
            .par_iter_mut()
            .zip(self.z.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, zc))| {
                let lo = c * CHUNK;
                let mut a = Acc::ZERO;
                for i in 0..zc.len() {
                    let zi = if p[lo + i] > 0.0 { r[lo + i] } else { 0.0 };
                    zc[i] = zi;
                    a.gt += g[lo + i] * zi;
                }
                *acc = a;
            });
        combine(&self.parts)
    }

    /// Step 2 with the preconditioned residual: `t = z + β t` on `I_c`, 0 elsewhere. Returns
    /// `Σ g t`, `Σ_W t`, `|W|`.
    fn direction_preconditioned(&mut self, beta: f64) -> Acc {
        let Work {
            p, g, z, t, parts, ..
        } = self;
        let z = &*z;
        rewrite_t(parts, t, p, g, |k, pk, gk, tk, a| {
            if pk > 0.0 {
                let ti = z[k] + beta * tk;
                a.n_w += 1;
                a.gt += gk * ti;
                a.st += ti;
                ti
            } else {
                0.0
            }
        })
    }

    /// Step 2: `t = g + β t` on the working set `W`, 0 elsewhere. `W = I_c`, or
    /// `I_c ∪ {g < 0}` for a steepest-descent step. Returns `Σ g t`, `Σ_W t`, `|W|`.
    fn direction(&mut self, beta: f64, steepest: bool) -> Acc {
        let Work { p, g, t, parts, .. } = self;
        rewrite_t(parts, t, p, g, |_, pk, gk, tk, a| {
            let ti = if pk > 0.0 {
                gk + beta * tk
            } else if steepest && gk < 0.0 {
                gk
            } else {
                0.0
            };
            if ti != 0.0 || pk > 0.0 {
                a.n_w += 1;
                a.gt += gk * ti;
                a.st += ti;
            }
            ti
        })
    }

    /// Step 3–4 reductions on `r = C t`: `Σ r t` (t vanishes off `W`) and, for load control
    /// (`with_mean`), `Σ_W r`.
    fn curvature(&mut self, steepest: bool, with_mean: bool) -> Acc {
        let (p, g, t, r) = (&self.p, &self.g, &self.t, &self.r);
        self.parts.par_iter_mut().enumerate().for_each(|(c, acc)| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(p.len());
            let mut a = Acc::ZERO;
            if with_mean {
                for i in lo..hi {
                    a.rt += r[i] * t[i];
                    if p[i] > 0.0 || (steepest && g[i] < 0.0) {
                        a.rw += r[i];
                    }
                }
            } else {
                a.rt = r[lo..hi]
                    .iter()
                    .zip(&t[lo..hi])
                    .fold(0.0, |s, (x, y)| s + x * y);
            }
            *acc = a;
        });
        combine(&self.parts)
    }

    /// The trial of a chord step: `p(τ)` = steps 5–6 applied to `p − τ t`, and `t ← d = p(τ) − p`
    /// (the whole change, truncations and `I_ol` entries included). Returns `Σ g d` (in `gt`)
    /// and the counts of the trial (`n_nl`: points where `p(τ) ≠ p − τ t`).
    fn chord(&mut self, tau: f64, tau_ol: f64) -> Acc {
        let Work { p, g, t, parts, .. } = self;
        rewrite_t(parts, t, p, g, |_, pk, gk, tk, a| {
            let lin = pk - tau * tk;
            let pn = Self::step_point(lin, gk, tau_ol, a);
            if pn != lin {
                a.n_nl += 1;
            }
            let d = pn - pk;
            a.gt += gk * d;
            d
        })
    }

    /// The chord step `p ← p + s d`, `g ← g + s r` with `d` in `t` and `r = C d`. For
    /// `0 < s ≤ 1` the new `p` lies between `p ≥ 0` and `p(τ) ≥ 0`; the clamp only removes
    /// round-off. Returns the reductions of the new state.
    fn chord_update(&mut self, s: f64) -> Acc {
        let Work {
            p, g, t, r, parts, ..
        } = self;
        let (t, r) = (&*t, &*r);
        parts
            .par_iter_mut()
            .zip(p.par_chunks_mut(CHUNK))
            .zip(g.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((acc, pc), gc))| {
                let lo = c * CHUNK;
                let len = pc.len();
                let (tc, rc) = (&t[lo..lo + len], &r[lo..lo + len]);
                let mut a = Acc::ZERO;
                for i in 0..len {
                    if tc[i] != 0.0 {
                        pc[i] = (pc[i] + s * tc[i]).max(0.0);
                    }
                    let gi = gc[i] + s * rc[i];
                    gc[i] = gi;
                    a.observe(pc[i], gi);
                }
                *acc = a;
            });
        combine(parts)
    }

    /// Largest `τ` with `p − τ t ≥ 0` (ratio test), `∞` if none limits it.
    fn ratio_test(&mut self) -> f64 {
        let (p, t) = (&self.p, &self.t);
        self.parts.par_iter_mut().enumerate().for_each(|(c, acc)| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(p.len());
            let mut m = f64::INFINITY;
            for i in lo..hi {
                if t[i] > 0.0 {
                    m = m.min(p[i] / t[i]);
                }
            }
            let mut a = Acc::ZERO;
            a.min_g = m;
            *acc = a;
        });
        combine(&self.parts).min_g
    }

    /// Steps 5–6 for one point from the linear step `lin = p − τ t`: truncation, and entry
    /// through `I_ol` with the gap `g` of step 1.
    #[inline(always)]
    fn step_point(lin: f64, g: f64, tau: f64, a: &mut Acc) -> f64 {
        // `tau` is `τ` of a plain step, `τ / C_00` of a preconditioned one (see `run`).
        let mut pn = lin;
        if pn < 0.0 {
            pn = 0.0;
            a.n_trunc += 1;
        }
        if pn == 0.0 && g < 0.0 {
            pn = -tau * g;
            a.n_ol += 1;
        }
        pn
    }

    /// Steps 5–6 fused with the incremental step 1 of the next iteration. Also counts the
    /// truncated points and `|I_ol|`, which make the incremental update inexact.
    ///
    /// * Displacement: `g ← g − τ r` (`u` is not touched); returns the reductions of the new
    ///   gap.
    /// * Load: `u ← u − τ r`; returns `Σ p`, `Σ_{I_c} (max h − h)`, `Σ_{I_c} u` of the unscaled
    ///   new state (the gap is written by the following [`Work::gap_pass`]).
    fn update(&mut self, tau: f64, tau_ol: f64, mode: Mode) -> Acc {
        let (h, hmax) = (self.h, self.hmax);
        let Work {
            p,
            u,
            g,
            t,
            r,
            slots,
            parts,
            ..
        } = self;
        let (t, r) = (&*t, &*r);
        match mode {
            Mode::Displacement(_) => parts
                .par_iter_mut()
                .zip(slots.par_chunks_mut(SPARSE_MAX))
                .zip(p.par_chunks_mut(CHUNK))
                .zip(g.par_chunks_mut(CHUNK))
                .enumerate()
                .for_each(|(c, (((acc, sl), pc), gc))| {
                    let lo = c * CHUNK;
                    let len = pc.len();
                    let (tc, rc) = (&t[lo..lo + len], &r[lo..lo + len]);
                    let mut a = Acc::ZERO;
                    for i in 0..len {
                        let lin = pc[i] - tau * tc[i];
                        let pn = Self::step_point(lin, gc[i], tau_ol, &mut a);
                        if pn != lin {
                            record(sl, &mut a, lo + i, pn - lin);
                        }
                        pc[i] = pn;
                        let gi = gc[i] - tau * rc[i];
                        gc[i] = gi;
                        a.observe(pn, gi);
                    }
                    *acc = a;
                }),
            Mode::Load(_) => parts
                .par_iter_mut()
                .zip(slots.par_chunks_mut(SPARSE_MAX))
                .zip(p.par_chunks_mut(CHUNK))
                .zip(u.par_chunks_mut(CHUNK))
                .enumerate()
                .for_each(|(c, (((acc, sl), pc), uc))| {
                    let lo = c * CHUNK;
                    let len = pc.len();
                    let (hc, gc) = (&h[lo..lo + len], &g[lo..lo + len]);
                    let (tc, rc) = (&t[lo..lo + len], &r[lo..lo + len]);
                    let mut a = Acc::ZERO;
                    for i in 0..len {
                        let lin = pc[i] - tau * tc[i];
                        let pn = Self::step_point(lin, gc[i], tau_ol, &mut a);
                        if pn != lin {
                            record(sl, &mut a, lo + i, pn - lin);
                        }
                        pc[i] = pn;
                        let ui = uc[i] - tau * rc[i];
                        uc[i] = ui;
                        if pn > 0.0 {
                            a.n_c += 1;
                            a.sum_p += pn;
                            a.sh += hmax - hc[i];
                            a.su += ui;
                        }
                    }
                    *acc = a;
                }),
        }
        combine(parts)
    }

    /// Gather the last update's changes `(index, d)` in index order (valid when
    /// `n_nl ≤ SPARSE_MAX`, so no chunk overflowed its slots).
    fn gather_changes(&mut self) {
        self.changes.clear();
        for (c, a) in self.parts.iter().enumerate() {
            let k = a.n_nl.min(SPARSE_MAX);
            self.changes
                .extend_from_slice(&self.slots[c * SPARSE_MAX..c * SPARSE_MAX + k]);
        }
    }

    /// Build the influence table `C e_0` on first use (one operator application, into `r`,
    /// which is scratch between an update and the next direction).
    fn ensure_table(&mut self) {
        if self.table.is_empty() {
            self.r.fill(0.0);
            self.r[0] = 1.0;
            // Its capacity was reserved (fallibly) with the other work arrays.
            let mut table = std::mem::take(&mut self.table).into_owned();
            table.resize(self.r.len(), 0.0);
            self.op.apply(&self.r, &mut table);
            self.applies += 1;
            self.table = Cow::Owned(table);
        }
    }

    /// Displacement control: `g ← g + C d` for the gathered changes, and the reductions of
    /// the corrected gap.
    fn correct_gap(&mut self) -> Acc {
        let (ny, nx, periodic) = (self.ny, self.nx, self.periodic);
        let Work {
            p,
            g,
            table,
            changes,
            parts,
            ..
        } = self;
        let (p, table, changes) = (&*p, &**table, &*changes);
        parts
            .par_iter_mut()
            .zip(g.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, gc))| {
                let lo = c * CHUNK;
                add_sparse(gc, lo, changes, table, ny, nx, periodic);
                let mut a = Acc::ZERO;
                for (&pi, &gi) in p[lo..lo + gc.len()].iter().zip(gc.iter()) {
                    a.observe(pi, gi);
                }
                *acc = a;
            });
        combine(parts)
    }

    /// Load control: `u ← u + C d` for the gathered changes, and `Σ p`, `Σ_{I_c} (max h − h)`,
    /// `Σ_{I_c} u` of the corrected state.
    fn correct_u(&mut self) -> Acc {
        let (ny, nx, periodic, h, hmax) = (self.ny, self.nx, self.periodic, self.h, self.hmax);
        let Work {
            p,
            u,
            table,
            changes,
            parts,
            ..
        } = self;
        let (p, table, changes) = (&*p, &**table, &*changes);
        parts
            .par_iter_mut()
            .zip(u.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, uc))| {
                let lo = c * CHUNK;
                add_sparse(uc, lo, changes, table, ny, nx, periodic);
                let mut a = Acc::ZERO;
                for (i, &ui) in uc.iter().enumerate() {
                    if p[lo + i] > 0.0 {
                        a.n_c += 1;
                        a.sum_p += p[lo + i];
                        a.sh += hmax - h[lo + i];
                        a.su += ui;
                    }
                }
                *acc = a;
            });
        combine(parts)
    }
}

/// Note a non-linear change `d` at `index` in a chunk's slots.
#[inline(always)]
fn record(slots: &mut [(usize, f64)], a: &mut Acc, index: usize, d: f64) {
    if a.n_nl < slots.len() {
        slots[a.n_nl] = (index, d);
    }
    a.n_nl += 1;
}

/// `out[k − lo] += Σ_(b, d) C_{k b} d` for the flat indices `k` of the chunk `out` starting at
/// `lo`, with `C` given by the table of [`Work::table`]. Each row segment is split where the
/// table index wraps or reflects so the inner loops run over contiguous slices; every element
/// adds the changes in their (index) order, whatever the thread count.
pub(crate) fn add_sparse(
    out: &mut [f64],
    lo: usize,
    changes: &[(usize, f64)],
    table: &[f64],
    ny: usize,
    nx: usize,
    periodic: bool,
) {
    let hi = lo + out.len();
    let mut start = lo;
    while start < hi {
        let i = start / nx;
        let ja = start % nx;
        let end = ((i + 1) * nx).min(hi);
        let jb = ja + (end - start);
        let seg = &mut out[start - lo..end - lo];
        for &(b, d) in changes {
            let (i0, j0) = (b / nx, b % nx);
            let row = if periodic {
                (i + ny - i0) % ny
            } else {
                i.abs_diff(i0)
            };
            let krow = &table[row * nx..(row + 1) * nx];
            // Columns j < j0 and j ≥ j0 of this segment.
            let split = j0.clamp(ja, jb);
            let (left, right) = seg.split_at_mut(split - ja);
            if !left.is_empty() {
                // Here ja < j0.
                if periodic {
                    // Table column j − j0 + nx.
                    let k0 = ja + nx - j0;
                    let n_left = left.len();
                    for (v, &k) in left.iter_mut().zip(&krow[k0..k0 + n_left]) {
                        *v += d * k;
                    }
                } else {
                    // Table column j0 − j, decreasing along the segment.
                    let k_hi = j0 - ja;
                    let k_lo = k_hi + 1 - left.len();
                    for (v, &k) in left.iter_mut().zip(krow[k_lo..=k_hi].iter().rev()) {
                        *v += d * k;
                    }
                }
            }
            if !right.is_empty() {
                // Here split ≥ j0: table column j − j0.
                let k0 = split - j0;
                let n_right = right.len();
                for (v, &k) in right.iter_mut().zip(&krow[k0..k0 + n_right]) {
                    *v += d * k;
                }
            }
        }
        start = end;
    }
}

#[derive(Clone, Copy, Debug)]
enum Mode {
    Displacement(f64),
    /// Target `Σ p = p̄ N`.
    Load(f64),
}

/// `x > 0` and not NaN.
#[inline]
fn positive(x: f64) -> bool {
    x > 0.0
}

/// Deterministic `(max, min, Σ)` of the heights.
fn height_stats(h: &[f64]) -> (f64, f64, f64) {
    let parts: Vec<(f64, f64, f64)> = h
        .par_chunks(CHUNK)
        .map(|c| {
            c.iter().fold(
                (f64::NEG_INFINITY, f64::INFINITY, 0.0),
                |(mx, mn, s), &v| (mx.max(v), mn.min(v), s + v),
            )
        })
        .collect();
    parts.iter().fold(
        (f64::NEG_INFINITY, f64::INFINITY, 0.0),
        |(mx, mn, s), &(a, b, c)| (mx.max(a), mn.min(b), s + c),
    )
}

/// The iteration. `start`: an initial pressure (`≥ 0`, `N` values) taken over as the iterate,
/// used instead of `opts.initial_pressure` (the coarse start; there is no warm start then).
fn run(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    start: Option<Vec<f64>>,
    finish: Finish,
) -> Result<Solution> {
    let (ny, nx) = (problem.ny, problem.nx);
    let n = ny * nx;
    let h = problem.heights;
    let (hmax, hmin, hsum) = height_stats(h);
    let hs = hmax - hmin;
    let c00 = love_displacement(0.0, 0.0, problem.dx, problem.e_star);
    let periodic = op.boundary == Boundary::Periodic;

    let mut at_limit = false;
    let mode = match control {
        Control::Approach(mut delta) => {
            if periodic {
                // Full contact of a periodic surface with zero-mean u: Σ g = N(max h − Δ − mean h).
                let limit = hmax - hsum / n as f64;
                let slack = 1e-12 * hs.max(hmax.abs()).max(hmin.abs());
                if delta > limit + slack {
                    return Err(Error::invalid(
                        "approach",
                        format!(
                            "{delta} exceeds the full-contact approach max h − mean h = {limit} of \
                             a periodic surface (u has zero mean, so the flat cannot move further)"
                        ),
                    ));
                }
                if delta >= limit {
                    delta = limit;
                    at_limit = true;
                }
            }
            Mode::Displacement(delta)
        }
        Control::MeanPressure(m) => Mode::Load(m * n as f64),
    };
    // The certificate's scale. A patch pressed far past its height range has gaps and
    // displacements of the order of Δ (or, in load control, of the displacement `p̄·C_00` that
    // the mean pressure makes at its own cell), so round-off is relative to those, not h_s:
    // at p̄ = 10⁴ E* on a 33² free patch Δ ≈ 10³ h_s, and a certificate relative to h_s
    // cannot go below ~1e-12. In load control Δ is an output, so the scale follows the
    // current Δ.
    let scale_at = |delta: f64| -> f64 {
        match control {
            Control::Approach(d) if hs > 0.0 => hs.max(d),
            Control::Approach(d) if d > 0.0 => d,
            Control::Approach(_) => 1.0,
            Control::MeanPressure(m) => {
                let s = hs.max(m * c00);
                if delta.is_finite() {
                    s.max(delta.abs())
                } else {
                    s
                }
            }
        }
    };
    let max_iter = opts.max_iter.unwrap_or_else(|| default_max_iter(n));

    let n_chunks = n.div_ceil(CHUNK);
    let sparse_max = sparse_limit(op.boundary);
    let u_in_r = matches!(mode, Mode::Displacement(_));
    let mut w = Work {
        op,
        h,
        hmax,
        p: match start {
            Some(p0) if p0.len() == n => p0,
            _ => alloc::try_zeroed(n, "the pressure field")?,
        },
        u: if u_in_r {
            Vec::new()
        } else {
            alloc::try_zeroed(n, "the displacement field")?
        },
        u_in_r,
        g: alloc::try_zeroed(n, "the gap field")?,
        t: alloc::try_zeroed(n, "the conjugate direction")?,
        r: alloc::try_zeroed(n, "the operator work field")?,
        table: match table {
            Some(k) => Cow::Borrowed(k),
            None => Cow::Owned(alloc::try_with_capacity(n, "the influence table")?),
        },
        slots: alloc::try_filled(
            n_chunks * SPARSE_MAX,
            (0, 0.0),
            "the sparse-correction slots",
        )?,
        changes: Vec::with_capacity(SPARSE_MAX),
        ny,
        nx,
        periodic,
        parts: vec![Acc::ZERO; n_chunks],
        applies: 0,
        pre: None,
        z: Vec::new(),
        pre_applies: 0,
    };
    if opts.precondition {
        let pre = Operator::inverse_compliance(ny, nx, problem.dx, problem.e_star)?;
        w.pre = Some(pre);
        w.z = alloc::try_zeroed(n, "the preconditioned residual")?;
    }

    // Initial pressure: the warm start, or p = 0 (displacement) / uniform p̄ (load, the paper's).
    if let Some(p0) = opts.initial_pressure {
        w.p.par_iter_mut()
            .zip(p0.par_iter())
            .for_each(|(p, &v)| *p = v.max(0.0));
    }
    if let Mode::Load(target) = mode {
        let sum = w.contact_sums().sum_p;
        if sum > 0.0 {
            w.scale_p(target / sum);
        } else {
            let pbar = target / n as f64;
            w.p.par_iter_mut().for_each(|v| *v = pbar);
        }
    }
    let any_p = w.p.par_iter().any(|&v| v > 0.0);
    if any_p {
        w.refresh_u();
    }
    let (mut state, mut delta) = w.evaluate(mode);
    let mut fresh = true;

    let mut it = 0usize;
    let mut cg = false; // the paper's δ
    let mut g_old = 1.0;
    // The last step was a preconditioned one (its `G = Σ g z` is what β continues from).
    let mut last_pre = false;
    let mut last_poll = Instant::now();
    let mut best_cert = f64::INFINITY;
    // Chord steps (and the β = 0 that goes with them) only where they are taken.
    let chords_on = opts.chord_steps && matches!(mode, Mode::Displacement(_));
    let mut chord = false;
    let mut chord_steps = 0usize;
    let (mut tau_pre, mut tau_plain) = (f64::NAN, f64::NAN);
    loop {
        let cert = state.certificate() / scale_at(delta);
        if w.pre.is_some() && cert > SAFEGUARD * best_cert {
            // The preconditioned iteration is not contracting: finish with plain steps.
            w.pre = None;
            cg = false;
        }
        best_cert = best_cert.min(cert);
        if cert <= opts.tol {
            if fresh || finish == Finish::Incremental {
                break;
            }
            // Converged on the incrementally updated u: confirm on a fresh product.
            w.refresh_u();
            (state, delta) = w.evaluate(mode);
            fresh = true;
            continue;
        }
        if it >= max_iter || !cert.is_finite() {
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer".into(),
            });
        }
        if let Some(stop) = opts.should_stop {
            if it % STOP_EVERY == 0 || last_poll.elapsed() >= STOP_INTERVAL {
                last_poll = Instant::now();
                if stop() {
                    return Err(Error::Interrupted);
                }
            }
        }

        // Step 2: the conjugate direction, or a steepest-descent step on I_c ∪ {g < 0} when
        // there is no contact set or the direction carries no descent.
        let mut steepest = state.n_c == 0;
        let mut preconditioned = false;
        let mut dir = Acc::ZERO;
        // Past half contact the preconditioned steps stop paying (measured: the same or more
        // iterations); the first steepest step from p = 0 can pass it briefly.
        if w.pre.is_some() && !steepest && state.n_c as f64 <= PRECONDITION_MAX_FRACTION * n as f64
        {
            // G = Σ_{I_c} g z; β continues only a preconditioned sequence.
            let gz = w.precondition().gt;
            let beta = if cg && !chord && last_pre && g_old > 0.0 {
                gz / g_old
            } else {
                0.0
            };
            dir = w.direction_preconditioned(beta);
            if positive(dir.gt) && positive(gz) {
                preconditioned = true;
                g_old = gz;
            }
        }
        if !preconditioned {
            let beta = if cg && !chord && !last_pre && !steepest && g_old > 0.0 {
                state.gg / g_old
            } else {
                0.0
            };
            dir = w.direction(beta, steepest);
            if !positive(dir.gt) && !steepest {
                steepest = true;
                dir = w.direction(0.0, true);
            }
        }
        if !positive(dir.gt) {
            // No descent anywhere: g vanishes on I_c and nothing overlaps, up to round-off
            // below the certificate's resolution.
            return Err(Error::NotConverged {
                iterations: it,
                residual: cert,
                what: "Polonsky–Keer".into(),
            });
        }
        if !preconditioned {
            g_old = if steepest { dir.gt } else { state.gg };
        }
        last_pre = preconditioned;

        // A chord step while the contact set is changing wholesale (displacement control):
        // the trial projected step `d = p(τ₀) − p` is applied through its own product `C d`,
        // so `g` stays exact with one product per iteration; the step length along `d` is
        // the exact minimiser of the energy on the chord, capped at 1 (feasible).
        if chord && !steepest {
            let tau0 = if preconditioned { tau_pre } else { tau_plain };
            if tau0.is_finite() && tau0 > 0.0 {
                let tau_ol0 = if preconditioned { tau0 / c00 } else { tau0 };
                let trial = w.chord(tau0, tau_ol0);
                if trial.gt < 0.0 {
                    w.op.apply(&w.t, &mut w.r);
                    w.applies += 1;
                    let drd = w.curvature(false, false).rt;
                    let s = if positive(drd) {
                        (-trial.gt / drd).min(1.0)
                    } else {
                        1.0
                    };
                    state = w.chord_update(s);
                    it += 1;
                    fresh = false;
                    cg = false;
                    let next = tau0
                        * if s < 1.0 {
                            s.max(CHORD_SHRINK_MIN)
                        } else {
                            CHORD_GROW
                        };
                    if preconditioned {
                        tau_pre = next;
                    } else {
                        tau_plain = next;
                    }
                    chord_steps += 1;
                    chord = wholesale(trial.n_nl, state.n_c, sparse_max);
                    continue;
                }
                // No descent on the chord: redo the direction, take a regular step.
                dir = if preconditioned {
                    w.direction_preconditioned(0.0)
                } else {
                    w.direction(0.0, false)
                };
            }
        }

        // Steps 3–4.
        w.op.apply(&w.t, &mut w.r);
        w.applies += 1;
        let curv = w.curvature(steepest, matches!(mode, Mode::Load(_)));
        let denom = match mode {
            Mode::Displacement(_) => curv.rt,
            Mode::Load(_) => curv.rt - curv.rw / dir.n_w.max(1) as f64 * dir.st,
        };
        let mut tau = dir.gt / denom;
        if !positive(denom) || !tau.is_finite() {
            tau = w.ratio_test();
            if !tau.is_finite() {
                return Err(Error::NotConverged {
                    iterations: it,
                    residual: cert,
                    what: "Polonsky–Keer (unbounded direction)".into(),
                });
            }
        }

        // Steps 5–6 (+ 1 on the incremental u).
        // Points entering through I_ol get `p = −τ g` (the paper's rule) after a plain step.
        // A preconditioned step's `τ` is dimensionless (≈ 1 when M ≈ C⁻¹); its entries get
        // `−τ g / C_00`, the pressure that closes the gap at that point alone, the softer of
        // the two local stiffness estimates (the diagonal of M overshoots and oscillates).
        let tau_ol = if preconditioned { tau / c00 } else { tau };
        // The last line-search lengths start the chord's trial length.
        if preconditioned {
            tau_pre = tau;
        } else if !steepest {
            tau_plain = tau;
        }
        let up = w.update(tau, tau_ol, mode);
        it += 1;
        // The paper's rule. After a steepest step on W, δ = 1 continues CG from that step
        // (G_old = Σ_W g²), which is exact when the set did not change.
        cg = up.n_ol == 0;
        // Bring u (displacement control: g) up to date with p. A linear step is already done
        // by the update pass; a few non-linear changes d get C d by direct summation; many
        // get a fresh product C p.
        let mut sparse = None;
        if up.n_nl > 0 && up.n_nl <= sparse_max {
            w.gather_changes();
            w.ensure_table();
            sparse = Some(match mode {
                Mode::Displacement(_) => w.correct_gap(),
                Mode::Load(_) => w.correct_u(),
            });
        }
        let now = sparse.unwrap_or(up);
        let consistent = up.n_nl <= sparse_max;
        chord = chords_on && wholesale(up.n_nl, up.n_c, sparse_max);
        match mode {
            Mode::Displacement(_) if consistent => {
                fresh = false;
                state = now;
            }
            Mode::Load(target) if consistent && now.n_c > 0 => {
                // Step 7 folded into the gap pass: p and u scale together.
                fresh = false;
                let s = target / now.sum_p;
                delta = (now.sh + s * now.su) / now.n_c as f64;
                state = w.gap_pass(delta, Some(s));
            }
            _ => {
                if let Mode::Load(target) = mode {
                    let sum = w.contact_sums().sum_p;
                    if sum > 0.0 {
                        w.scale_p(target / sum);
                    } else {
                        let pbar = target / n as f64;
                        w.p.par_iter_mut().for_each(|v| *v = pbar);
                    }
                }
                w.refresh_u();
                (state, delta) = w.evaluate(mode);
                fresh = true;
            }
        }
    }

    if at_limit {
        // Δ = max h − mean h of a periodic surface: p is defined up to a constant (C 1 = 0).
        // Return the least-load state, the limit of Δ ↑ max h − mean h, min p = 0.
        let pmin = w.p.par_iter().cloned().reduce(|| f64::INFINITY, f64::min);
        if pmin > 0.0 {
            w.p.par_iter_mut().for_each(|v| *v = (*v - pmin).max(0.0));
            w.refresh_u();
            (state, delta) = w.evaluate(mode);
        }
    }

    let kkt = state.certificate() / scale_at(delta);
    let sum_p = state.sum_p;
    let applies = w.applies;
    let pre_applies = w.pre_applies;
    let pressure = std::mem::take(&mut w.p);
    let gap = std::mem::take(&mut w.g);
    let displacement = if fresh {
        w.into_displacement()
    } else {
        // Finish::Incremental: `u` was updated incrementally (displacement control: `r` holds
        // the last `C t`).
        Vec::new()
    };
    Ok(Solution {
        ny,
        nx,
        pressure,
        displacement,
        gap,
        approach: delta,
        iterations: it,
        applies,
        preconditioner_applies: pre_applies,
        chord_steps,
        kkt,
        contact_points: state.n_c,
        plastic_points: 0,
        load: sum_p * problem.dx * problem.dx,
        mean_pressure: sum_p / n as f64,
        coarse: CoarseCost::default(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::kkt::kkt_certificate;
    use crate::elastic::operator::dense_apply;
    use std::f64::consts::PI;

    fn lcg(seed: u64, n: usize) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    /// A rough-ish random surface: white noise smoothed by a 3×3 (periodic) box filter.
    fn rough(ny: usize, nx: usize, seed: u64) -> Vec<f64> {
        let w = lcg(seed, ny * nx);
        let mut h = vec![0.0; ny * nx];
        for i in 0..ny {
            for j in 0..nx {
                let mut s = 0.0;
                for di in [ny - 1, 0, 1] {
                    for dj in [nx - 1, 0, 1] {
                        s += w[((i + di) % ny) * nx + (j + dj) % nx];
                    }
                }
                h[i * nx + j] = s / 9.0;
            }
        }
        h
    }

    fn problem(h: &[f64], ny: usize, nx: usize, boundary: Boundary) -> Problem<'_> {
        Problem {
            heights: h,
            ny,
            nx,
            dx: 0.7,
            e_star: 1.3,
            boundary,
        }
    }

    fn opts(tol: f64) -> Options<'static> {
        Options {
            tol,
            ..Options::default()
        }
    }

    /// Dense `C` (row-major `n × n`) by applying the operator to unit vectors.
    fn dense_matrix_from_operator(op: &Operator) -> Vec<f64> {
        let n = op.ny * op.nx;
        let mut c = vec![0.0; n * n];
        let mut e = vec![0.0; n];
        let mut col = vec![0.0; n];
        for j in 0..n {
            e[j] = 1.0;
            op.apply(&e, &mut col);
            e[j] = 0.0;
            for i in 0..n {
                c[i * n + j] = col[i];
            }
        }
        c
    }

    /// Exact solution of `min ½pᵀCp − bᵀp, p ≥ 0` for a small dense SPD `C`: projected
    /// Gauss–Seidel to find the active set, then a Cholesky solve on it, repeated until KKT
    /// holds to round-off.
    fn dense_reference(c: &[f64], b: &[f64]) -> Vec<f64> {
        let n = b.len();
        let mut p = vec![0.0; n];
        for _round in 0..200 {
            for _ in 0..2000 {
                for i in 0..n {
                    let gi: f64 = (0..n).map(|j| c[i * n + j] * p[j]).sum::<f64>() - b[i];
                    p[i] = (p[i] - gi / c[i * n + i]).max(0.0);
                }
            }
            let act: Vec<usize> = (0..n).filter(|&i| p[i] > 0.0).collect();
            let k = act.len();
            // Cholesky of C_PP.
            let mut l = vec![0.0; k * k];
            for a in 0..k {
                for bb in 0..=a {
                    let mut s = c[act[a] * n + act[bb]];
                    for m in 0..bb {
                        s -= l[a * k + m] * l[bb * k + m];
                    }
                    if a == bb {
                        l[a * k + a] = s.sqrt();
                    } else {
                        l[a * k + bb] = s / l[bb * k + bb];
                    }
                }
            }
            let mut z: Vec<f64> = act.iter().map(|&i| b[i]).collect();
            for a in 0..k {
                for m in 0..a {
                    z[a] -= l[a * k + m] * z[m];
                }
                z[a] /= l[a * k + a];
            }
            for a in (0..k).rev() {
                for m in a + 1..k {
                    z[a] -= l[m * k + a] * z[m];
                }
                z[a] /= l[a * k + a];
            }
            let mut q = vec![0.0; n];
            for (a, &i) in act.iter().enumerate() {
                q[i] = z[a];
            }
            let g: Vec<f64> = (0..n)
                .map(|i| (0..n).map(|j| c[i * n + j] * q[j]).sum::<f64>() - b[i])
                .collect();
            let bs = b.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
            if q.iter().all(|&v| v >= 0.0) && g.iter().all(|&v| v >= -1e-13 * bs) {
                return q;
            }
        }
        panic!("dense reference did not converge");
    }

    fn max_rel(a: &[f64], b: &[f64]) -> f64 {
        let s = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / s
    }

    #[test]
    fn matches_dense_exact_solution_free() {
        for &(ny, nx, seed) in &[(9usize, 9usize, 1u64), (12, 7, 2), (7, 12, 3)] {
            let h = rough(ny, nx, seed);
            let pr = problem(&h, ny, nx, Boundary::Free);
            let ker = Kernel::new(ny, nx, pr.dx, pr.e_star);
            let n = ny * nx;
            let c: Vec<f64> = (0..n * n).map(|k| ker.coeff(k / n, k % n)).collect();
            let (hmax, hmin, _) = height_stats(&h);
            for frac in [0.1, 0.4, 0.8, 1.5] {
                let delta = frac * (hmax - hmin);
                let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
                let exact = dense_reference(&c, &b);
                let s = solve(&pr, Control::Approach(delta), &opts(1e-12)).unwrap();
                let e = max_rel(&s.pressure, &exact);
                assert!(e < 1e-8, "{ny}x{nx} Δ*={frac}: rel err {e}");
                assert!(s.kkt <= 1e-12);
                // Reported gap is the documented formula with a fresh u = C p.
                let u = dense_apply(&ker, &s.pressure);
                for i in 0..n {
                    let g = hmax - delta - h[i] + u[i];
                    assert!((g - s.gap[i]).abs() < 1e-12 * (hmax - hmin));
                }
                // Load control with the same mean pressure reaches the same state.
                let l = solve(&pr, Control::MeanPressure(s.mean_pressure), &opts(1e-12)).unwrap();
                assert!(max_rel(&l.pressure, &exact) < 1e-8);
                assert!(
                    (l.approach - delta).abs() < 1e-9 * (hmax - hmin),
                    "{} vs {delta}",
                    l.approach
                );
            }
        }
    }

    #[test]
    fn chord_steps_reach_the_exact_minimiser() {
        // From p = 0 the early iterations truncate or add a large part of the contact set at
        // once, so they are chord steps (one product of the whole change); the answer must
        // still be the exact minimiser, found here by a dense projected Gauss–Seidel and
        // Cholesky on its contact set.
        let (ny, nx) = (24usize, 24usize);
        let mut chords = 0;
        for seed in [5u64, 6] {
            let h = rough(ny, nx, seed);
            let pr = problem(&h, ny, nx, Boundary::Free);
            let ker = Kernel::new(ny, nx, pr.dx, pr.e_star);
            let n = ny * nx;
            let c: Vec<f64> = (0..n * n).map(|k| ker.coeff(k / n, k % n)).collect();
            let (hmax, hmin, _) = height_stats(&h);
            for frac in [0.3, 0.6, 1.0] {
                let delta = frac * (hmax - hmin);
                let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
                let exact = dense_reference(&c, &b);
                for precondition in [true, false] {
                    let o = Options {
                        precondition,
                        ..opts(1e-12)
                    };
                    let s = solve(&pr, Control::Approach(delta), &o).unwrap();
                    chords += s.chord_steps;
                    let regular = Options {
                        chord_steps: false,
                        ..o
                    };
                    let r = solve(&pr, Control::Approach(delta), &regular).unwrap();
                    assert_eq!(r.chord_steps, 0);
                    assert!(max_rel(&r.pressure, &exact) < 1e-8);
                    assert!(s.chord_steps < s.iterations);
                    let ca: Vec<bool> = s.pressure.iter().map(|&p| p > 0.0).collect();
                    let ce: Vec<bool> = exact.iter().map(|&p| p > 0.0).collect();
                    assert_eq!(ca, ce, "seed {seed} Δ*={frac} pre {precondition}");
                    let e = max_rel(&s.pressure, &exact);
                    assert!(e < 1e-8, "seed {seed} Δ*={frac}: rel err {e}");
                    assert!(s.kkt <= 1e-12);
                    // Load control takes no chord steps, so the option changes nothing there.
                    let l = solve(&pr, Control::MeanPressure(s.mean_pressure), &o).unwrap();
                    assert_eq!(l.chord_steps, 0);
                    assert!(max_rel(&l.pressure, &exact) < 1e-8);
                    let lr = solve(&pr, Control::MeanPressure(s.mean_pressure), &regular).unwrap();
                    assert_eq!((l.iterations, l.applies), (lr.iterations, lr.applies));
                    assert_eq!(l.pressure, lr.pressure);
                }
            }
        }
        assert!(chords > 0, "no chord step was taken");
    }

    #[test]
    fn preconditioned_and_plain_reach_the_same_minimiser() {
        // Larger than the dense tests, so the preconditioned conjugate steps run for many
        // iterations; both iterations must land on the same contact set and pressures.
        let (ny, nx) = (48usize, 40usize);
        let h = rough(ny, nx, 7);
        let (hmax, hmin, hsum) = height_stats(&h);
        let mut used = 0;
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            let top = match boundary {
                Boundary::Free => hmax - hmin,
                Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
            };
            for frac in [0.2, 0.5, 0.9] {
                let delta = frac * top;
                let plain = Options {
                    precondition: false,
                    ..opts(1e-12)
                };
                let a = solve(&pr, Control::Approach(delta), &opts(1e-12)).unwrap();
                let b = solve(&pr, Control::Approach(delta), &plain).unwrap();
                used += a.preconditioner_applies;
                assert_eq!(b.preconditioner_applies, 0);
                let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
                let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
                assert_eq!(ca, cb, "{boundary:?} Δ*={frac}");
                let e = max_rel(&a.pressure, &b.pressure);
                assert!(e < 1e-8, "{boundary:?} Δ*={frac}: rel diff {e}");
                assert!(a.kkt <= 1e-12 && b.kkt <= 1e-12);
            }
        }
        assert!(used > 0, "no preconditioned step was taken");
    }

    #[test]
    fn coarse_start_and_cold_start_reach_the_same_minimiser() {
        // Large enough for two coarse levels (97 → 49 → 25 per side).
        let (ny, nx) = (97usize, 100usize);
        let h = rough(ny, nx, 13);
        let (hmax, hmin, hsum) = height_stats(&h);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            let top = match boundary {
                Boundary::Free => hmax - hmin,
                Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
            };
            let mut controls: Vec<Control> = [0.1, 0.3, 0.6]
                .iter()
                .map(|f| Control::Approach(f * top))
                .collect();
            let cold = Options {
                coarse_start: false,
                ..opts(1e-12)
            };
            let mid = solve(&pr, Control::Approach(0.3 * top), &cold).unwrap();
            controls.push(Control::MeanPressure(mid.mean_pressure));
            for control in controls {
                let a = solve(&pr, control, &opts(1e-12)).unwrap();
                let b = solve(&pr, control, &cold).unwrap();
                assert_eq!(b.coarse, CoarseCost::default());
                // Two levels, or one when nothing touches on the coarsest (its highest node
                // is lower than the fine summit).
                let levels = a.coarse.levels;
                assert!(
                    (1..=2).contains(&levels),
                    "{boundary:?} {control:?}: {levels}"
                );
                assert!(a.coarse.applies > 0);
                let ratio = a.coarse.applies_fine_equivalent / a.coarse.applies as f64;
                assert!(ratio > 0.0 && ratio < 0.26, "{ratio}");
                let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
                let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
                assert_eq!(ca, cb, "{boundary:?} {control:?}");
                let e = max_rel(&a.pressure, &b.pressure);
                assert!(e < 1e-8, "{boundary:?} {control:?}: rel diff {e}");
                assert!(a.kkt <= 1e-12 && b.kkt <= 1e-12);
                assert!((a.approach - b.approach).abs() < 1e-9 * (hmax - hmin));
            }
        }
        // A warm start or a small grid skips the coarse levels.
        let pr = problem(&h, ny, nx, Boundary::Free);
        let first = solve(&pr, Control::Approach(0.1), &Options::default()).unwrap();
        let warm = Options {
            initial_pressure: Some(&first.pressure),
            ..Options::default()
        };
        let s = solve(&pr, Control::Approach(0.2), &warm).unwrap();
        assert_eq!(s.coarse, CoarseCost::default());
        let small = rough(40, 70, 3);
        let s = solve(
            &problem(&small, 40, 70, Boundary::Free),
            Control::Approach(0.1),
            &Options::default(),
        )
        .unwrap();
        assert_eq!(s.coarse.levels, 0);
    }

    #[test]
    fn matches_dense_exact_solution_periodic() {
        let (ny, nx) = (8usize, 10usize);
        let h = rough(ny, nx, 11);
        let pr = problem(&h, ny, nx, Boundary::Periodic);
        let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
        let c = dense_matrix_from_operator(&op);
        let (hmax, hmin, hsum) = height_stats(&h);
        let limit = hmax - hsum / (ny * nx) as f64;
        for frac in [0.2, 0.5, 0.9] {
            let delta = frac * limit;
            let b: Vec<f64> = h.iter().map(|&v| delta - (hmax - v)).collect();
            let exact = dense_reference(&c, &b);
            let s = solve_with_operator(&op, &pr, Control::Approach(delta), &opts(1e-12)).unwrap();
            let e = max_rel(&s.pressure, &exact);
            assert!(e < 1e-8, "Δ={frac}·limit: rel err {e}");
            let l = solve_with_operator(
                &op,
                &pr,
                Control::MeanPressure(s.mean_pressure),
                &opts(1e-12),
            )
            .unwrap();
            assert!(max_rel(&l.pressure, &exact) < 1e-8);
            assert!((l.approach - delta).abs() < 1e-9 * (hmax - hmin));
        }
    }

    #[test]
    fn certificate_meets_tolerance_and_is_honest() {
        let (ny, nx) = (40usize, 33usize);
        let h = rough(ny, nx, 5);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            for (control, tol) in [
                (Control::Approach(0.05), DEFAULT_TOL),
                (Control::Approach(0.2), 1e-8),
                (Control::MeanPressure(0.02), DEFAULT_TOL),
            ] {
                let s = solve(&pr, control, &opts(tol)).unwrap();
                assert!(s.kkt <= tol, "{boundary:?} {control:?}: {}", s.kkt);
                let (hmax, hmin, _) = height_stats(&h);
                // The documented scale: max(h_s, Δ), or max(h_s, |Δ|, p̄·C_00) under a load.
                let c00 = love_displacement(0.0, 0.0, pr.dx, pr.e_star);
                let scale = match control {
                    Control::Approach(d) => (hmax - hmin).max(d),
                    Control::MeanPressure(m) => (hmax - hmin).max(s.approach.abs()).max(m * c00),
                };
                let again = kkt_certificate(&s.pressure, &s.gap, scale);
                assert_eq!(again, s.kkt);
                assert!(s.pressure.iter().all(|&v| v >= 0.0));
                assert_eq!(
                    s.contact_points,
                    s.pressure.iter().filter(|&&v| v > 0.0).count()
                );
                let sum: f64 = s.pressure.iter().sum();
                assert!((s.load - sum * pr.dx * pr.dx).abs() <= 1e-12 * s.load);
                // Δ = max h − h_i + u_i − g_i everywhere.
                for ((&hi, &ui), &gi) in h.iter().zip(&s.displacement).zip(&s.gap) {
                    let d = hmax - hi + ui - gi;
                    assert!((d - s.approach).abs() < 1e-12 * (hmax - hmin));
                }
            }
        }
    }

    #[test]
    fn load_control_reaches_displacement_state() {
        let (ny, nx) = (64usize, 48usize);
        let h = rough(ny, nx, 8);
        let (hmax, hmin, _) = height_stats(&h);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            let delta = 0.3 * (hmax - hmin);
            let d = solve(&pr, Control::Approach(delta), &opts(1e-12)).unwrap();
            let l = solve(&pr, Control::MeanPressure(d.mean_pressure), &opts(1e-12)).unwrap();
            assert!(max_rel(&l.pressure, &d.pressure) < 1e-8);
            assert!((l.approach - delta).abs() < 1e-9 * (hmax - hmin));
            assert!((l.mean_pressure - d.mean_pressure).abs() < 1e-12 * d.mean_pressure);
        }
    }

    #[test]
    fn periodic_westergaard() {
        // h = A cos(2πx/λ) along axis 1, uniform along axis 0: the contact half-width a obeys
        // p̄/p* = sin²(πa/λ), p* = π E* A/λ, and full contact starts at p̄ = p*.
        let (ny, nx) = (8usize, 512usize);
        let (dx, e_star, amp) = (1.0 / 512.0, 2.0, 0.01);
        let lambda = nx as f64 * dx;
        let h: Vec<f64> = (0..ny * nx)
            .map(|k| amp * (2.0 * PI * (k % nx) as f64 * dx / lambda).cos())
            .collect();
        let pr = Problem {
            heights: &h,
            ny,
            nx,
            dx,
            e_star,
            boundary: Boundary::Periodic,
        };
        let p_star = PI * e_star * amp / lambda;
        for ratio in [0.1, 0.25, 0.5, 0.75, 0.9] {
            let s = solve(&pr, Control::MeanPressure(ratio * p_star), &opts(1e-11)).unwrap();
            assert_eq!(s.contact_points % ny, 0);
            let a = (s.contact_points / ny) as f64 * dx / 2.0;
            let a_exact = lambda / PI * ratio.sqrt().asin();
            let e = (a - a_exact).abs() / a_exact;
            assert!(e < 0.01, "p̄/p* = {ratio}: a = {a}, exact {a_exact} ({e})");
        }
        // Full contact starts at p*: just below, a gap remains; just above, none.
        let below = solve(&pr, Control::MeanPressure(0.99 * p_star), &opts(1e-11)).unwrap();
        assert!(below.contact_points < ny * nx);
        let above = solve(&pr, Control::MeanPressure(1.01 * p_star), &opts(1e-11)).unwrap();
        assert_eq!(above.contact_points, ny * nx);
        assert!((above.approach - amp).abs() < 1e-9 * amp);
        // Displacement control at the limit Δ = max h − mean h returns the full-contact
        // state at its onset, p̄ = p*; beyond it is an error, not a hang.
        let s = solve(&pr, Control::Approach(amp), &opts(1e-11)).unwrap();
        assert!(s.kkt <= 1e-11);
        assert!(
            (s.mean_pressure - p_star).abs() < 1e-6 * p_star,
            "{} vs {p_star}",
            s.mean_pressure
        );
        // Near the trough p and g both vanish; the certificate bounds −g and g on I_c, and the
        // few free trough points are left with gaps of the same order.
        assert!(s.gap.iter().all(|g| g.abs() <= 1e-9 * 2.0 * amp));
        match solve(&pr, Control::Approach(1.01 * amp), &opts(1e-11)) {
            Err(Error::InvalidArgument { name, message }) => {
                assert_eq!(name, "approach");
                assert!(message.contains("0.01"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn one_and_two_threads_agree() {
        let (ny, nx) = (96usize, 100usize);
        let h = rough(ny, nx, 21);
        let pr = problem(&h, ny, nx, Boundary::Free);
        let run = |threads: usize, control: Control| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| solve(&pr, control, &Options::default()).unwrap())
        };
        for control in [Control::Approach(0.1), Control::MeanPressure(0.01)] {
            let a = run(1, control);
            let b = run(2, control);
            assert_eq!(a.iterations, b.iterations);
            assert!(max_rel(&a.pressure, &b.pressure) <= 1e-12);
            assert!(max_rel(&a.gap, &b.gap) <= 1e-12);
            assert!((a.approach - b.approach).abs() <= 1e-12 * a.approach.abs());
        }
    }

    #[test]
    fn warm_start_agrees_with_cold() {
        let (ny, nx) = (64usize, 64usize);
        let h = rough(ny, nx, 33);
        let (hmax, hmin, _) = height_stats(&h);
        let hs = hmax - hmin;
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            let first = solve(&pr, Control::Approach(0.2 * hs), &Options::default()).unwrap();
            for control in [
                Control::Approach(0.3 * hs),
                Control::MeanPressure(1.5 * first.mean_pressure),
            ] {
                let cold = solve(&pr, control, &Options::default()).unwrap();
                let warm = solve(
                    &pr,
                    control,
                    &Options {
                        initial_pressure: Some(&first.pressure),
                        ..Options::default()
                    },
                )
                .unwrap();
                assert!(warm.kkt <= DEFAULT_TOL && cold.kkt <= DEFAULT_TOL);
                // A gap residual ε·h_s moves p by about ε·h_s/C_00 relative to p ~ Δ/C_00.
                assert!(
                    max_rel(&warm.pressure, &cold.pressure) < 1e-7,
                    "{boundary:?} {control:?}: {}",
                    max_rel(&warm.pressure, &cold.pressure)
                );
                assert!((warm.approach - cold.approach).abs() < 1e-8 * hs);
            }
        }
    }

    #[test]
    fn trivial_states() {
        let (ny, nx) = (10usize, 9usize);
        let h = rough(ny, nx, 4);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            // Δ = 0: nothing is pressed, p = 0 without iterating.
            let s = solve(&pr, Control::Approach(0.0), &Options::default()).unwrap();
            assert_eq!(s.iterations, 0);
            assert!(s.pressure.iter().all(|&v| v == 0.0));
            assert_eq!(s.kkt, 0.0);
        }
        // A flat surface: free punch (displacement and load control agree).
        let flat = vec![0.5; ny * nx];
        let pr = problem(&flat, ny, nx, Boundary::Free);
        let d = solve(&pr, Control::Approach(0.1), &Options::default()).unwrap();
        assert_eq!(d.contact_points, ny * nx);
        let l = solve(
            &pr,
            Control::MeanPressure(d.mean_pressure),
            &Options::default(),
        )
        .unwrap();
        assert!((l.approach - 0.1).abs() < 1e-8);
        // One point.
        let one = [3.0];
        let pr = problem(&one, 1, 1, Boundary::Free);
        let s = solve(&pr, Control::MeanPressure(2.0), &Options::default()).unwrap();
        assert!((s.pressure[0] - 2.0).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let (ny, nx) = (6usize, 5usize);
        let h = rough(ny, nx, 9);
        let pr = problem(&h, ny, nx, Boundary::Free);
        let name = |r: Result<Solution>| match r {
            Err(Error::InvalidArgument { name, .. }) => name,
            other => panic!("{other:?}"),
        };
        let d = Control::Approach(0.1);
        let o = Options::default();
        let mut hn = h.clone();
        hn[7] = f64::NAN;
        assert_eq!(
            name(solve(&problem(&hn, ny, nx, Boundary::Free), d, &o)),
            "heights"
        );
        assert_eq!(
            name(solve(&problem(&h[1..], ny, nx, Boundary::Free), d, &o)),
            "heights"
        );
        assert_eq!(
            name(solve(&problem(&[], 0, 5, Boundary::Free), d, &o)),
            "heights"
        );
        assert_eq!(name(solve(&Problem { dx: 0.0, ..pr }, d, &o)), "dx");
        assert_eq!(
            name(solve(&Problem { e_star: -1.0, ..pr }, d, &o)),
            "e_star"
        );
        assert_eq!(
            name(solve(
                &Problem {
                    e_star: f64::NAN,
                    ..pr
                },
                d,
                &o
            )),
            "e_star"
        );
        assert_eq!(name(solve(&pr, Control::Approach(-0.1), &o)), "approach");
        assert_eq!(
            name(solve(&pr, Control::Approach(f64::INFINITY), &o)),
            "approach"
        );
        assert_eq!(
            name(solve(&pr, Control::MeanPressure(0.0), &o)),
            "mean_pressure"
        );
        assert_eq!(
            name(solve(&pr, Control::MeanPressure(f64::NAN), &o)),
            "mean_pressure"
        );
        assert_eq!(name(solve(&pr, d, &opts(0.0))), "tol");
        assert_eq!(name(solve(&pr, d, &opts(f64::NAN))), "tol");
        let short = vec![0.0; 3];
        let bad_init = Options {
            initial_pressure: Some(&short),
            ..Options::default()
        };
        assert_eq!(name(solve(&pr, d, &bad_init)), "initial_pressure");
        let mut nan_init = vec![0.0; ny * nx];
        nan_init[0] = f64::NAN;
        let bad_init = Options {
            initial_pressure: Some(&nan_init),
            ..Options::default()
        };
        assert_eq!(name(solve(&pr, d, &bad_init)), "initial_pressure");
        let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
        assert_eq!(name(solve_with_operator(&op, &pr, d, &o)), "operator");

        // Memory limit, iteration cap, interruption.
        let small = Options {
            memory_limit: Some(1000),
            ..Options::default()
        };
        assert!(matches!(solve(&pr, d, &small), Err(Error::TooLarge { .. })));
        let capped = Options {
            max_iter: Some(1),
            ..opts(1e-14)
        };
        match solve(&pr, Control::Approach(0.3), &capped) {
            Err(Error::NotConverged {
                iterations, what, ..
            }) => {
                assert_eq!(iterations, 1);
                assert_eq!(what, "Polonsky–Keer");
            }
            other => panic!("{other:?}"),
        }
        let calls = std::sync::atomic::AtomicUsize::new(0);
        let stop = || {
            calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            true
        };
        let interrupt = Options {
            should_stop: Some(&stop),
            ..Options::default()
        };
        assert_eq!(
            solve(&pr, Control::Approach(0.3), &interrupt).unwrap_err(),
            Error::Interrupted
        );
        assert_eq!(calls.load(std::sync::atomic::Ordering::Relaxed), 1);
    }

    #[test]
    fn sparse_correction_equals_operator() {
        // Chunks of CHUNK points cut rows in the middle on this grid.
        let (ny, nx) = (70usize, 93usize);
        let n = ny * nx;
        for periodic in [false, true] {
            let op = if periodic {
                Operator::periodic(ny, nx, 0.3, 2.0)
            } else {
                Operator::free(&Kernel::new(ny, nx, 0.3, 2.0))
            };
            let mut e0 = vec![0.0; n];
            e0[0] = 1.0;
            let mut table = vec![0.0; n];
            op.apply(&e0, &mut table);
            let idx = [
                0usize,
                5,
                nx - 1,
                nx,
                2 * nx + 17,
                4095,
                4096,
                n / 2,
                n - nx,
                n - 1,
            ];
            let vals = lcg(77, idx.len());
            let changes: Vec<(usize, f64)> = idx.iter().copied().zip(vals).collect();
            let mut d = vec![0.0; n];
            for &(b, v) in &changes {
                d[b] = v;
            }
            let mut want = vec![0.0; n];
            op.apply(&d, &mut want);
            let mut got = vec![0.0; n];
            for (c, out) in got.chunks_mut(CHUNK).enumerate() {
                add_sparse(out, c * CHUNK, &changes, &table, ny, nx, periodic);
            }
            let e = max_rel(&got, &want);
            assert!(e < 1e-12, "periodic={periodic}: {e}");
            if !periodic {
                // The Love kernel table, which free solves use instead of the product C e_0,
                // against the same FFT oracle.
                let love = Kernel::new(ny, nx, 0.3, 2.0).table;
                let mut got = vec![0.0; n];
                for (c, out) in got.chunks_mut(CHUNK).enumerate() {
                    add_sparse(out, c * CHUNK, &changes, &love, ny, nx, false);
                }
                let e = max_rel(&got, &want);
                assert!(e < 1e-12, "Love table: {e}");
                // The oracle catches a table off by one column.
                let mut shifted = love.clone();
                for i in 0..ny {
                    for j in 0..nx - 1 {
                        shifted[i * nx + j] = love[i * nx + j + 1];
                    }
                }
                let mut bad = vec![0.0; n];
                for (c, out) in bad.chunks_mut(CHUNK).enumerate() {
                    add_sparse(out, c * CHUNK, &changes, &shifted, ny, nx, false);
                }
                assert!(max_rel(&bad, &want) > 1e-3);
            }
        }
    }

    #[test]
    fn caller_kernel_table_and_incremental_finish() {
        let (ny, nx) = (48usize, 45usize);
        let h = rough(ny, nx, 21);
        let (hmax, hmin, hsum) = height_stats(&h);
        for boundary in [Boundary::Free, Boundary::Periodic] {
            let pr = problem(&h, ny, nx, boundary);
            let top = match boundary {
                Boundary::Free => hmax - hmin,
                Boundary::Periodic => hmax - hsum / (ny * nx) as f64,
            };
            let (op, table) = match boundary {
                Boundary::Free => {
                    let k = Kernel::new(ny, nx, pr.dx, pr.e_star);
                    (Operator::free(&k), k.table)
                }
                Boundary::Periodic => {
                    let op = Operator::periodic(ny, nx, pr.dx, pr.e_star);
                    let mut e0 = vec![0.0; ny * nx];
                    e0[0] = 1.0;
                    let mut t = vec![0.0; ny * nx];
                    op.apply(&e0, &mut t);
                    (op, t)
                }
            };
            for f in [0.2, 0.5] {
                let control = Control::Approach(f * top);
                let o = opts(1e-12);
                let a = solve_with_operator(&op, &pr, control, &o).unwrap();
                let b = solve_with_kernel(&op, Some(&table), &pr, control, &o).unwrap();
                let ca: Vec<bool> = a.pressure.iter().map(|&p| p > 0.0).collect();
                let cb: Vec<bool> = b.pressure.iter().map(|&p| p > 0.0).collect();
                assert_eq!(ca, cb, "{boundary:?} {f}");
                assert!(max_rel(&a.pressure, &b.pressure) < 1e-8);
                assert!(b.kkt <= 1e-12);
                // The given table spares the product that builds it (when the sparse path ran).
                assert!(b.applies <= a.applies, "{} vs {}", b.applies, a.applies);
                // An incremental finish stops on the updated state: the same contact set at a
                // looser tolerance, no confirming product, no displacement unless fresh.
                let loose = opts(1e-6);
                let c = solve_level(&pr, control, &loose, Finish::Confirmed, 0).unwrap();
                let d = solve_level(&pr, control, &loose, Finish::Incremental, 0).unwrap();
                assert!(d.applies <= c.applies);
                assert_eq!(c.iterations, d.iterations);
                assert_eq!(c.pressure, d.pressure);
                assert!(d.displacement.is_empty() || d.displacement == c.displacement);
            }
            let short = vec![0.0; ny * nx - 1];
            assert!(
                solve_with_kernel(&op, Some(&short), &pr, Control::Approach(0.1), &opts(1e-8))
                    .is_err()
            );
        }
    }
}
