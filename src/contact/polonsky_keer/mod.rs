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
//! alone does not reset `δ`. The paper resets `δ = 0` on any non-empty `I_ol`; here only an
//! `I_ol` of more than [`OL_KEEP_FRACTION`] of the contact set does, because near the solution
//! a few boundary points re-enter in almost every step and the paper's rule turns the
//! iteration into a steepest descent there (see [`OL_KEEP_FRACTION`]).
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
//! regular iteration restarts (`δ = 0`) anyway.
//!
//! Under load control the trial is scaled to the load first (step 7), so the chord keeps it:
//!
//! ```text
//! q = P(p − τ₀ t),  d = q · p̄N / Σ q − p   (Σ d = 0)
//! r = C d,  s = min(1, −Σ g d / Σ d r),  p ← p + s d,  u ← u + s r
//! ```
//!
//! With `Σ d = 0` the approach term `−Δ Σ p` of the energy is constant on the chord, so `s` is
//! again its exact minimiser for any `Δ`; `Δ` and the gap are then taken from the new `u` as in
//! step 1 (with the rescale of step 7 removing the round-off of `Σ p`). Without chord steps load
//! control paid two products in most of its early iterations: at 1025² and 2049² (RMD
//! D = 2.2, free, tol 1e-8, Δ = 0.6 h_s) 60 and 92 fine products against 43 and 65 under
//! displacement control at the same contact state; with them 37 and 51.
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
//! # Rescaled load steps (displacement control)
//!
//! At the same contact state load control used to take fewer iterations than displacement
//! control (at 2049², `Δ` = 0.3/0.6 h_s: 57/73 against 71/93). Its steps move on the plane
//! `Σ p = const`: the line search sees `C` with the mean over the working set taken out
//! (step 3), and step 7 rescales `p`. The uniform mode on a scattered contact set is what
//! the preconditioner `E*|q|/2`, made for the whole plane, gets least right, and load control
//! never has to find it by iterating. With [`Options::rescaled_steps`] (the default) a
//! displacement-controlled solve of a free surface that starts from a pressure (the coarse
//! start's, or a caller's warm start) takes load control's steps at the load of its current iterate: the
//! line search of step 4 with the mean of `r` over the working set removed, and chord trials
//! scaled to the current load (`Σ d = 0`). After each step `p` is scaled by
//!
//! ```text
//! k = (N_c Δ − Σ_{I_c} (max h − h)) / Σ_{I_c} u,    p ← k p,   g ← g + (k − 1) u
//! ```
//!
//! so the gap at the imposed `Δ` has zero mean over `I_c`. `u = g − (max h − Δ) + h` is read
//! back from the gap, so no displacement field is kept and the passes stay those of
//! displacement control, plus the rescale's two (`Work::rescale` in `passes.rs`: one for
//! the sums, one to scale). This is load control whose load follows the approach. The gap is always the one at
//! the imposed `Δ`, so the certificate and the answer are those of displacement control, and
//! the reported approach is `Δ` exactly. At the solution `k = 1` (there
//! `u = Δ − (max h − h)` on `I_c`). The product that confirms convergence is not rescaled,
//! so the returned `u` is `C p` of the returned `p`.
//!
//! Where `k` is not usable, the solve continues with the plain displacement steps from that
//! iterate (no contact, `Σ_{I_c} u ≤ 0`, or `k ≤ 0`). `k ≤ 0` means the set holds points
//! the flat at `Δ` does not reach even undeformed, as a start with pressure everywhere does
//! at a light load. From `p = 0` (no coarse start: fewer than [`COARSE_START_MIN_SIDE`]
//! points a side) the steps are the plain ones.
//!
//! Periodic surfaces keep the plain steps. Measured on periodic RMD surfaces (same settings,
//! `Δ` = 0.1/0.3 of the height range, medians of 3), the rescaled steps took 34.7/68.4 FFT
//! products against 35.4/77.4 at 1025², but 48.4/110.6 against 46.4/102.1 at 2049². A
//! threshold search at 1025² (14 warm-started solves near 46 % contact,
//! `benchmarks/threshold_speed.py`) took the same 507–509 iterations with them and 10–15 %
//! more time, for the two rescale passes. Every step must be rescaled, including those after a fresh product: with one
//! rescale missed after each wholesale change (those iterations refresh `u`), the load
//! wandered and a 1025², `Δ` = 0.6 h_s solve took 1566 iterations.
//!
//! Tried before and not kept: an exact line search along `p` itself after every step
//! (`p ← (1+s) p`, `s = −Σ p g / Σ p u`). It breaks the conjugate sequence (231 products
//! against 184 at 4097², `Δ` = 0.6 h_s). A first version of the rescaled steps ran load
//! control's own passes, with a displacement field kept and the gap recomputed from it in
//! each step. It took the same iterates but cost one pass more per iteration, and at 2049²,
//! `Δ` = 0.6 h_s it was slower than the plain steps (9.4 against 9.2 s).
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
//! skip both their forward and their inverse row FFT, as `z` is only used on `I_c`; the
//! masking of `g` and of `z` to `I_c` happens inside the row passes,
//! [`Operator::apply_restricted`], and `z` is written into the work field `r`); measured at 257², tol 1e-12,
//! it takes 1.2–2.8× fewer iterations (see [`PRECONDITION_MAX_FRACTION`]); the answer is
//! the same minimiser (identical contact sets in every test).
//!
//! The preconditioner cannot share the transform of the step's product `C t`: it acts on `g`
//! restricted to `I_c`, and the restriction does not commute with the transform (updating
//! `M χ g` by `−τ M χ C t` needs the transform of `χ C t`, a second pair anyway). Its pairs are
//! counted apart ([`Solution::preconditioner_products`]) and made in `f32` alongside the
//! operator's `f32` products ("Single-precision products" below); at 2049², free, `Δ = 0.3 h_s` (RMD
//! D = 2.2, tol 1e-8) 71 pairs on the 2160² grid (73.3 with the coarse levels' share), about
//! 20 products of the 4096² padded grid by transform size, next to 92.9 products
//! (`benchmarks/results/contact_scale.md`).
//!
//! # Single-precision products
//!
//! While the certificate is above [`Options::single_precision_above`] (default
//! [`crate::contact::problem::DEFAULT_SINGLE_PRECISION_ABOVE`] `= 1e-4`), the products `C t`,
//! `C d` and `C p` of the iteration are made by the operator's `f32` twin
//! ([`crate::elastic::transform::Operator32`]: the same transform with the kernel spectrum,
//! the half spectrum and the FFTs in `f32`, relative error below `1e-6` of `max |u|`). Linear
//! convergence takes 20–30 iterations from a warm start to a certificate of `1e-3`, and a
//! product error of `~1e-6` is harmless while the certificate is far above it. When the
//! certificate falls to the switch level (or to `tol`, if that is higher), `u = C p` is
//! recomputed in `f64`.
//!
//! Below the switch level only the full products `u = C p` are `f64`; the increments `C t`,
//! `C d` of a chord step, and `C d` of the non-linear changes of a step that changes more
//! points than direct summation takes (`Work::correct_dense`; above the switch such a step
//! gets a fresh product `C p`) stay `f32`. An increment's error is about `1e-6` of the increment
//! itself, not of `u`: after a fresh `f64` product at certificate `c₀` the remaining steps
//! move the gap by some `c₀ h_s` in all, so the `f32` increments leave it within about
//! `1e-6 · c₀ h_s` of the gap a fresh product would give, and each fresh product starts
//! again from the exact `u`. `u = C p` is made afresh in `f64` each time the certificate has
//! fallen [`driver::REFRESH_RATIO`] `= 10⁻²` below its value at the previous fresh product
//! (at `1e-4`, `1e-6`, `1e-8` from the default switch), which keeps that drift near
//! `1e-12 h_s` below a certificate of `1e-6` and `1e-14 h_s` below `1e-8`. The convergence test is always
//! made on a fresh `f64` product, so the returned fields and the certificate are double
//! precision as without the switch. The sparse corrections use the `f64` influence table
//! throughout. [`Solution::single_products`] counts the `f32` products (included in
//! `fft_products`). A switch level `≤ tol` (e.g. `0`) turns both off; so does a finishing
//! tolerance above the level.
//!
//! With the operator's twin in use, the preconditioner's products (the inverse compliance,
//! `Work::precondition` in `passes.rs`) are made by its own `f32` twin too, above and below the
//! switch: an approximate preconditioner changes the rate a little, not the answer, and
//! the certificate is still that of `f64` products.
//!
//! The many-point corrections were fresh `f64` products `C p` until they too became `f32`
//! increments. At 4097², free, `Δ = 0.3 h_s` (RMD D = 2.2, seed 0, tol 1e-8), they were 20
//! of the solve's 23 `f64` products (of 119); the same 88 iterations and contact set then
//! took 33.3 s against 37.1 s with 3 `f64` products left (`benchmarks/results/contact_scale.md`).
//!
//! What the `f32` increments below the switch and the `f32` preconditioner bought, 20-level
//! RMD sweeps (D = 2.2, seed 0, free, the sweep's certificate `1e-9`, no flow; one process
//! each, one after the other on an idle machine; CPU s by `time.process_time`, iterations):
//!
//! | grid | before | `f32` increments | `f32` preconditioner | both |
//! |---|---|---|---|---|
//! | 513² | 10.2 s, 1018 | 9.2 s, 1016 | | |
//! | 1025² | 69.3 s, 1393 | 60.9 s, 1390 | 62.0 s, 1382 | 58.1 s, 1382 |
//! | 2049² | 417.4 s, 1962 (220.4 s wall) | | | 365.8 s, 1964 (194.6 s wall) |
//!
//! Loads within 3.1e-9 relative and free volumes within 1.8e-9 of the sweep before (the
//! certificate's bound, `docs/conventions.md`), contact counts identical at every level (2049²).
//! A single warm level is a noisier measure: the iteration count of one solve moves by tens
//! either way with the rounding (2049², Δ = 0.45 → 0.5 h_s from the previous pressure: 112
//! iterations before, 113–146 with `f32` increments depending on the refresh ratio, 116 in
//! `f64` throughout).
//!
//! What the early `f32` products bought (before the increments below the switch were `f32`
//! too), cold free solves of RMD D = 2.2 seed 0 (`h_s` = range, tol 1e-8, coarse
//! start; CPU seconds by `time.process_time`, machine shared, load average 5.7–6.1, one run
//! each; iterations / products (of which f32) / CPU s):
//!
//! | size | Δ/h_s | f64 throughout | switch 1e-4 | switch 1e-5 |
//! |---|---|---|---|---|
//! | 1025² | 0.1 | 28 / 33 / 1.70 | 28 / 34 (19) / 1.65 | 28 / 34 (22) / 1.41 |
//! | 1025² | 0.3 | 54 / 65 / 3.68 | 54 / 66 (34) / 2.66 | 54 / 66 (45) / 2.43 |
//! | 1025² | 0.6 | 67 / 86 / 4.02 | 65 / 84 (44) / 3.46 | 65 / 84 (58) / 3.43 |
//! | 2049² | 0.1 | 35 / 43 / 7.78 | 35 / 44 (23) / 7.55 | 35 / 44 (29) / 7.59 |
//! | 2049² | 0.3 | 71 / 90 / 17.27 | 81 / 104 (54) / 16.51 | 81 / 104 (70) / 16.10 |
//! | 2049² | 0.6 | 108 / 146 / 29.11 | 94 / 131 (68) / 23.91 | 95 / 131 (90) / 22.39 |
//!
//! (switch 1e-3 at 1025²: 28/34 (12)/1.69, 54/66 (23)/2.63, 64/83 (31)/3.69.) Contact sets
//! identical to the f64 solve in every case but one point at 1025², Δ = 0.6 h_s, switch 1e-5;
//! loads within 2·10⁻⁸ relative, gaps within 1.2·10⁻⁸ h_s. The `f32` iterates take a
//! slightly different path, so the iteration count moves either way (2049², 0.3 h_s: +10;
//! 0.6 h_s: −14). The CPU saving is 3–28 %, smaller at 2049² than the FFT speed ratio
//! suggests: the preconditioner products and the fused passes stay `f64`, and the products
//! after the switch are as before. The 2049² runs shared the machine with a compile.
//!
//! In a sweep, whose levels start warm from the previous one, fewer iterations run above the
//! switch: the 21-level 1025² RMD sweep (`benchmarks/sweep_scale_bench.py`) took 78.5 s CPU
//! without the flow against 82.6 s with `f64` products (−5 %), 154.2 against 154.7 s with it
//! (`benchmarks/results/sweep_scale.md`).
//!
//! The `f32` preconditioner was first tried in the early phase alone, on single cold solves
//! on a shared machine (1025², switch 1e-4: Δ = 0.3 h_s 54 iterations, 2.65 s CPU against
//! 2.56 s with the `f64` preconditioner; Δ = 0.6 h_s 68 iterations, 3.60 s against 65,
//! 3.61 s) and looked like no saving; over whole sweeps, with the `f32` increments, it saves
//! 5 % (table above).
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

pub mod coarse;
mod driver;
mod passes;
mod sparse;
#[cfg(test)]
mod tests;
mod validate;

use std::time::Duration;

pub use coarse::{COARSE_START_MIN_SIDE, COARSE_TOL, MAX_COARSE_LEVELS};
pub(crate) use driver::height_stats;
use driver::{run, Begin};
pub(crate) use sparse::add_sparse;
pub use validate::check_hardness;
pub(crate) use validate::validate;

pub use crate::contact::problem::{CoarseCost, Control, Options, Problem, Solution, DEFAULT_TOL};
use crate::elastic::kernel::{try_coarsened_table, Kernel};
use crate::elastic::memory;
use crate::elastic::operator::Operator;
use crate::error::{Error, Result};
use crate::grid::Boundary;

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
/// iteration but more (steepest-descent) iterations; 0.5 % kept the whole solve time within
/// a few per cent of the best of these while any `I_ol` entry reset the conjugate direction.
/// Since small entries keep it ([`OL_KEEP_FRACTION`]) the regular steps converge faster and
/// 2 % pays: RMD D = 2.2, tol 1e-8, `Δ` in units of the height range, products (fine +
/// coarse share) 0.5 % → 2 %, displacement / load control at the same contact state: free
/// 1025² `Δ` = 0.1/0.3/0.6 h_s 36.4/74.9/106.5 → 34.4/66.9/89.5 and 32.1/53.6/78.8 →
/// 32.1/53.6/68.8; free 2049² `Δ` = 0.3/0.6 h_s 101.9/146.4 → 92.9/150.4 and 80.7/99.8 →
/// 74.7/102.8; periodic 1025² `Δ` = 0.1/0.3/0.45 h_s 34.4/84.4/110.2 → 33.4/75.4/96.2 and
/// 33.3/77.3/107.9 → 34.3/71.3/85.9; periodic 2049² `Δ` = 0.3/0.45 h_s 105.1/136.3 →
/// 100.1/131.3 and 122.9/150.8 → 119.9/129.8 (`benchmarks/results/contact_scale.md`). The
/// preconditioner's pairs fall with the iterations.
pub const CHORD_FRACTION: f64 = 0.02;

/// The chord's trial length `τ₀` grows by this factor after a step that used the whole chord
/// (`s = 1`) and shrinks to `max(s, CHORD_SHRINK_MIN) τ₀` otherwise. Tried at 1025² (RMD
/// D = 2.2, free, tol 1e-8, `Δ` = 0.1/0.3/0.6 h_s, default 34.4/66.9/89.5 products, fine +
/// coarse share) and not kept: growth ×3 37.4/64.3/96.9; a fixed preconditioned trial
/// length `τ₀ = 1` (the Barzilai–Borwein length when `M ≈ C⁻¹`) 76.5/134.1/268.7, `τ₀ = 0.5`
/// 43.4/93.5/128.3; the conjugate direction continued through chord steps 40.5/68.4/108.1;
/// plain (not preconditioned) chord steps 44.1/76.8/108.4 (fewer preconditioner pairs,
/// still more FFT work in all); `benchmarks/results/contact_scale.md`.
const CHORD_GROW: f64 = 1.5;
const CHORD_SHRINK_MIN: f64 = 0.1;

/// Whether `changed` truncations and `I_ol` entries out of `n_c` contact points make the
/// next step a chord step.
fn wholesale(changed: usize, n_c: usize, sparse_max: usize) -> bool {
    changed > sparse_max && changed as f64 > CHORD_FRACTION * n_c as f64
}

/// A step whose `I_ol` entries are at most this fraction of the contact set keeps `δ = 1`
/// (the conjugate direction continues); the paper resets `δ = 0` on any entry. Near the
/// solution a few boundary points leave by truncation and re-enter through `I_ol` in almost
/// every step, most of all under load control, whose `Δ` moves every gap a little each step:
/// with the paper's rule the iteration there is a (preconditioned) steepest descent that
/// zig-zags at a rate of about 0.9 per step. Measured with chord steps above 0.5 % of the
/// contact set changing (before [`CHORD_FRACTION`] became 2 %), RMD D = 2.2, free, tol
/// 1e-8, `Δ` in units of the height range, products fine + coarse, paper's rule → this rule:
/// 1025² `Δ` = 0.3/0.6 h_s displacement 77.9 → 74.9, 108.5 → 106.5; load at the same
/// contact state `Δ` = 0.1/0.6 h_s 35.1 → 32.1, 145.8 → 78.8; 2049² `Δ` = 0.3 h_s
/// displacement 115.9 → 101.9, load 143.7 → 80.7. A fraction of 100 % gave the counts of
/// 1 % at 1025²; 0.1 % gave counts within ±1 product at 1025² and 104.9 / 88.7 at 2049².
/// Every step is still checked for descent (`Σ g t > 0`, else steepest).
pub const OL_KEEP_FRACTION: f64 = 0.01;

/// Whether a step with `n_ol` entries through `I_ol` into a contact set of `n_c` points keeps
/// the conjugate direction (`δ = 1`).
pub(crate) fn keeps_conjugacy(n_ol: usize, n_c: usize) -> bool {
    n_ol as f64 <= OL_KEEP_FRACTION * n_c as f64
}

/// `should_stop` is polled at least every this many iterations…
const STOP_EVERY: usize = 10;
/// …and at least this often on grids where ten iterations take long.
const STOP_INTERVAL: Duration = Duration::from_millis(250);

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
pub fn solve(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<Solution> {
    solve_level(
        problem,
        control,
        opts,
        initial,
        Finish::Confirmed,
        MAX_COARSE_LEVELS,
        None,
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

/// [`solve`] ending as `finish` says, with at most `levels` coarse levels below it. `finer`:
/// the free Love table (and its columns) of the grid this one coarsens, if there is one; this
/// level's table is then its leading block times two ([`try_coarsened_table`]).
pub(crate) fn solve_level(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
    finish: Finish,
    levels: usize,
    finer: Option<(&[f64], usize)>,
) -> Result<Solution> {
    validate_elastic(problem, control, opts, initial)?;
    check_memory(problem, opts)?;
    let kernel = coarsened_kernel(problem, finer)?;
    // The coarse levels run before the fine operator exists, so their memory is not added
    // to its.
    let own = kernel.as_ref().map(|k| (k.table.as_slice(), problem.nx));
    let start = (
        initial,
        coarse_start(problem, control, opts, initial, levels, own)?,
    );
    let (op, kernel) = operator_with(problem, kernel)?;
    let table = kernel.as_ref().map(|k| k.table.as_slice());
    run_from(&op, table, problem, control, opts, start, finish)
}

/// The influence table of a level as the `finer` table of its coarse levels: a free level's
/// (the Love table) with its columns; `None` for a periodic level, whose table is the
/// circulant's.
pub(crate) fn finer_table<'a>(
    problem: &Problem,
    table: Option<&'a [f64]>,
) -> Option<(&'a [f64], usize)> {
    match problem.boundary {
        Boundary::Free => table.map(|t| (t, problem.nx)),
        Boundary::Periodic => None,
    }
}

/// A free level's Love kernel from `finer`, the table (and its columns) of the grid it
/// coarsens by two ([`try_coarsened_table`]); `None` without one or for a periodic level.
pub(crate) fn coarsened_kernel(
    problem: &Problem,
    finer: Option<(&[f64], usize)>,
) -> Result<Option<Kernel>> {
    let (ny, nx) = (problem.ny, problem.nx);
    Ok(match (problem.boundary, finer) {
        (Boundary::Free, Some((table, fine_nx))) => Some(Kernel::from_table(
            ny,
            nx,
            problem.dx,
            problem.e_star,
            try_coarsened_table(table, fine_nx, ny, nx)?,
        )),
        _ => None,
    })
}

/// The operator of `problem` from its free Love `kernel` when one is given, else
/// [`operator_for`].
pub(crate) fn operator_with(
    problem: &Problem,
    kernel: Option<Kernel>,
) -> Result<(Operator, Option<Kernel>)> {
    match kernel {
        Some(k) => Ok((Operator::try_free(&k)?, Some(k))),
        None => operator_for(problem),
    }
}

/// The FFT operator of `problem`, and (free boundary) the Love kernel it is built from, whose
/// table is the influence table `C e_0` of the sparse corrections: kept instead of being
/// rebuilt by a product. The periodic operator builds that table on first use.
pub(crate) fn operator_for(problem: &Problem) -> Result<(Operator, Option<Kernel>)> {
    let (ny, nx) = (problem.ny, problem.nx);
    match problem.boundary {
        Boundary::Free => {
            let kernel = Kernel::try_new(ny, nx, problem.dx, problem.e_star)?;
            let op = Operator::try_free(&kernel)?;
            Ok((op, Some(kernel)))
        }
        Boundary::Periodic => Ok((
            Operator::try_periodic(ny, nx, problem.dx, problem.e_star)?,
            None,
        )),
    }
}

/// The coarse-level start of a cold solve, if [`Options::coarse_start`] asks for one. `table`:
/// the problem's free Love table (and its columns), from which the coarse levels take theirs.
fn coarse_start(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
    levels: usize,
    table: Option<(&[f64], usize)>,
) -> Result<CoarseStart> {
    if levels > 0 && coarse::applies_to(problem.ny, problem.nx, opts, initial) {
        coarse::start(problem, control, opts, levels, |p, c, o, below| {
            solve_level(p, c, o, None, Finish::Incremental, below, table)
        })
    } else {
        Ok(None)
    }
}

/// The prolonged pressure of a coarse start and what its levels cost.
type CoarseStart = Option<(Vec<f64>, CoarseCost)>;

/// [`run`] from the warm start `initial`, else from the coarse start (reporting its cost), else
/// from zero.
fn run_from(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
    control: Control,
    opts: &Options,
    start: (Option<&[f64]>, CoarseStart),
    finish: Finish,
) -> Result<Solution> {
    match start {
        (Some(p0), _) => run(op, table, problem, control, opts, Begin::Warm(p0), finish),
        (None, Some((p0, cost))) => {
            // The start pressure becomes the iterate (no second N-vector).
            let mut sol = run(op, table, problem, control, opts, Begin::Coarse(p0), finish)?;
            sol.coarse = cost;
            Ok(sol)
        }
        (None, None) => run(op, table, problem, control, opts, Begin::Zero, finish),
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
    initial: Option<&[f64]>,
) -> Result<Solution> {
    solve_with_kernel(op, None, problem, control, opts, initial)
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
    initial: Option<&[f64]>,
) -> Result<Solution> {
    validate_elastic(problem, control, opts, initial)?;
    check_operator(op, table, problem)?;
    let start = (
        initial,
        coarse_start(
            problem,
            control,
            opts,
            initial,
            MAX_COARSE_LEVELS,
            finer_table(problem, table),
        )?,
    );
    run_from(op, table, problem, control, opts, start, Finish::Confirmed)
}

/// The inputs, and no finite hardness: the capped problem is [`crate::contact::capped`]'s.
fn validate_elastic(
    problem: &Problem,
    control: Control,
    opts: &Options,
    initial: Option<&[f64]>,
) -> Result<()> {
    validate(problem, control, opts, initial)?;
    if opts.hardness.is_some_and(f64::is_finite) {
        return Err(Error::invalid(
            "hardness",
            "the elastic Polonsky–Keer iteration takes no finite hardness; capped solves are \
             contact::capped's",
        ));
    }
    Ok(())
}

/// [`Error::TooLarge`] when [`memory::polonsky_keer`] exceeds the options' memory limit.
pub(crate) fn check_memory(problem: &Problem, opts: &Options) -> Result<()> {
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

/// The caller's operator and influence table fit `problem` (shape and boundary; `dx` and
/// `E*` are trusted).
pub(crate) fn check_operator(
    op: &Operator,
    table: Option<&[f64]>,
    problem: &Problem,
) -> Result<()> {
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
    Ok(())
}

pub(super) fn boundary_name(b: Boundary) -> &'static str {
    match b {
        Boundary::Free => "free",
        Boundary::Periodic => "periodic",
    }
}
