//! The fused passes of one iteration: each sweeps the grid once in fixed chunks of
//! [`CHUNK`] points, updating the fields and reducing what the step needs (gap, certificate,
//! `G`, `Σ g t`, `Σ r t`, …) chunk by chunk, combined in chunk order.

use std::borrow::Cow;

use rayon::iter::Either;
use rayon::prelude::*;

use super::{CHUNK, SPARSE_MAX};
use crate::elastic::operator::Operator;
use crate::elastic::transform::Operator32;

/// `x > 0` and not NaN.
#[inline]
pub(super) fn positive(x: f64) -> bool {
    x > 0.0
}

/// What the iteration holds fixed: the approach, or the total `Σ p = p̄ N`.
#[derive(Clone, Copy, Debug)]
pub(super) enum Mode {
    Displacement(f64),
    /// Target `Σ p = p̄ N`.
    Load(f64),
}

/// Partial results of one fused pass over a chunk; combined in chunk order.
#[derive(Clone, Copy, Debug)]
pub(super) struct Acc {
    /// Points with `p > 0`.
    pub(super) n_c: usize,
    /// Σ p.
    pub(super) sum_p: f64,
    /// Σ p |g|.
    pub(super) sum_pg: f64,
    /// Σ_{I_c} g².
    pub(super) gg: f64,
    /// min g over all points.
    pub(super) min_g: f64,
    /// max |g| over `I_c`.
    pub(super) max_gc: f64,
    /// Non-finite gaps seen (overflow guard).
    pub(super) bad: usize,
    /// Σ g t (direction pass).
    pub(super) gt: f64,
    /// Σ_W t (direction pass).
    pub(super) st: f64,
    /// Points of the working set (direction pass).
    pub(super) n_w: usize,
    /// Σ r t (curvature pass).
    pub(super) rt: f64,
    /// Σ_W r (curvature pass).
    pub(super) rw: f64,
    /// Σ_{I_c} (max h − h), Σ_{I_c} u (load control: the approach).
    pub(super) sh: f64,
    pub(super) su: f64,
    /// Points clamped to zero / entering through `I_ol` in the update pass.
    pub(super) n_trunc: usize,
    pub(super) n_ol: usize,
    /// Points whose new pressure differs from the linear step `p − τ t` (truncated or in
    /// `I_ol`): the support of the correction `d`.
    pub(super) n_nl: usize,
}

impl Acc {
    pub(super) const ZERO: Acc = Acc {
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

    pub(super) fn merge(self, o: &Acc) -> Acc {
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
    pub(super) fn observe(&mut self, p: f64, g: f64) {
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

    /// Account one point for load control's step 7: `Σ p`, and over `I_c` the count,
    /// `Σ (max h − h)` (`rise` = `max h − h`) and `Σ u`.
    #[inline(always)]
    pub(super) fn observe_load(&mut self, p: f64, rise: f64, u: f64) {
        if p > 0.0 {
            self.n_c += 1;
            self.sum_p += p;
            self.sh += rise;
            self.su += u;
        }
    }

    /// Unscaled `max(−min g, max_{I_c} |g|, Σ p|g| / Σ p)`.
    pub(super) fn certificate(&self) -> f64 {
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
pub(super) struct Work<'a> {
    pub(super) op: &'a Operator,
    /// While set, the products `C t` and `C p` of the iteration use this `f32` twin of `op`
    /// (the early iterations, see the module documentation).
    pub(super) single: Option<&'a Operator32>,
    /// Whether the full products `C p` use `single` too (above the switch level); below it
    /// only the increments `C t` do, and `u = C p` is refreshed in `f64`.
    pub(super) single_full: bool,
    /// Products made by `single` (included in `applies`).
    pub(super) single_applies: usize,
    pub(super) h: &'a [f64],
    pub(super) hmax: f64,
    pub(super) p: Vec<f64>,
    pub(super) u: Vec<f64>,
    pub(super) g: Vec<f64>,
    pub(super) t: Vec<f64>,
    pub(super) r: Vec<f64>,
    /// `u` lives in `r` (displacement control).
    pub(super) u_in_r: bool,
    /// Influence of a unit pressure at point 0, `C e_0` (row-major `ny × nx`): the caller's
    /// kernel table, or built on first use by one product: free,
    /// `C_{ab} = table[|Δi|, |Δj|]`; periodic, `table[Δi mod ny, Δj mod nx]`.
    pub(super) table: Cow<'a, [f64]>,
    /// Per chunk, up to [`SPARSE_MAX`] `(index, d)` of the last update's non-linear changes.
    pub(super) slots: Vec<(usize, f64)>,
    /// Scratch list of all changes in index order.
    pub(super) changes: Vec<(usize, f64)>,
    /// Below the switch level (only then: empty otherwise), the last update's non-linear
    /// changes `d` as a field, zero elsewhere and zero again once applied: too many for
    /// direct summation, they are applied by one `f32` increment product `C d` instead of
    /// a fresh `f64` product `C p` ([`Work::correct_dense`]).
    pub(super) changes_field: Vec<f64>,
    pub(super) ny: usize,
    pub(super) nx: usize,
    pub(super) periodic: bool,
    pub(super) parts: Vec<Acc>,
    pub(super) applies: usize,
    /// Preconditioner (periodic inverse compliance on the `ny × nx` grid) and the number of
    /// its applications; the preconditioned residual `z = M g` on `I_c` lives in `r`.
    pub(super) pre: Option<Operator>,
    pub(super) pre_applies: usize,
}

pub(super) fn combine(parts: &[Acc]) -> Acc {
    parts.iter().fold(Acc::ZERO, |a, b| a.merge(b))
}

/// `t_k ← f(k, p_k, g_k, t_k, acc)` over the fixed chunks, each chunk's reductions in its
/// `acc`; returns them combined. The passes that rewrite `t` (the directions, the chord trial).
pub(super) fn rewrite_t(
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
    /// `u = C p` (in `f32` while [`Work::single`] is set).
    pub(super) fn refresh_u(&mut self) {
        let u = if self.u_in_r {
            &mut self.r
        } else {
            &mut self.u
        };
        match self.single {
            Some(s) if self.single_full => {
                s.apply(&self.p, u);
                self.single_applies += 1;
            }
            _ => self.op.apply(&self.p, u),
        }
        self.applies += 1;
    }

    /// Whether the full products `C p` are made in `f32` (above the switch level).
    pub(super) fn full_in_single(&self) -> bool {
        self.single.is_some() && self.single_full
    }

    /// `r = C t` (in `f32` while [`Work::single`] is set).
    pub(super) fn product_t(&mut self) {
        match self.single {
            Some(s) => {
                s.apply(&self.t, &mut self.r);
                self.single_applies += 1;
            }
            None => self.op.apply(&self.t, &mut self.r),
        }
        self.applies += 1;
    }

    /// Applies the last update's non-linear changes `d` (the changes field) by one increment
    /// product `C d`, in `f32` when the twin is in use, and zeroes the field in the same pass.
    /// Displacement control: `g ← g + C d` and the reductions of the corrected gap; load
    /// control: `u ← u + C d` and `Σ p`, `Σ_{I_c} (max h − h)`, `Σ_{I_c} u` of the corrected
    /// state (as [`Work::correct_gap`] and [`Work::correct_u`] for a few changes).
    ///
    /// An `f32` product errs by about `1e-6` of `|C d|`, the size of the step's correction,
    /// not of `u`: the same drift as the increments `C t`, bounded by the same `f64`
    /// refreshes (module documentation).
    pub(super) fn correct_dense(&mut self, mode: Mode) -> Acc {
        match self.single {
            Some(s) => {
                s.apply(&self.changes_field, &mut self.r);
                self.single_applies += 1;
            }
            None => self.op.apply(&self.changes_field, &mut self.r),
        }
        self.applies += 1;
        let (h, hmax) = (self.h, self.hmax);
        let Work {
            p,
            u,
            g,
            r,
            parts,
            changes_field,
            ..
        } = self;
        let (p, r) = (&*p, &*r);
        // Displacement control corrects the gap, load control the displacement.
        let field = match mode {
            Mode::Displacement(_) => g,
            Mode::Load(_) => u,
        };
        parts
            .par_iter_mut()
            .zip(field.par_chunks_mut(CHUNK))
            .zip(changes_field.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((acc, vc), fc))| {
                let lo = c * CHUNK;
                let len = vc.len();
                let (pc, rc, hc) = (&p[lo..lo + len], &r[lo..lo + len], &h[lo..lo + len]);
                fc.fill(0.0);
                let mut a = Acc::ZERO;
                for i in 0..len {
                    let v = vc[i] + rc[i];
                    vc[i] = v;
                    match mode {
                        Mode::Displacement(_) => a.observe(pc[i], v),
                        Mode::Load(_) => a.observe_load(pc[i], hmax - hc[i], v),
                    }
                }
                *acc = a;
            });
        combine(parts)
    }

    /// The displacement field of the last fresh product.
    pub(super) fn into_displacement(self) -> Vec<f64> {
        if self.u_in_r {
            self.r
        } else {
            self.u
        }
    }

    /// `p ← s p`.
    pub(super) fn scale_p(&mut self, s: f64) {
        self.p.par_iter_mut().for_each(|v| *v *= s);
    }

    /// `g = (max h − Δ) − h + u`, optionally scaling `p` and `u` by `s` first (load control,
    /// step 7 folded into the next gap evaluation); reductions for the certificate and `G`.
    pub(super) fn gap_pass(&mut self, delta: f64, s: Option<f64>) -> Acc {
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
    pub(super) fn contact_sums(&mut self) -> Acc {
        let (h, u, p, hmax) = (self.h, &self.u, &self.p, self.hmax);
        self.parts.par_iter_mut().enumerate().for_each(|(c, acc)| {
            let lo = c * CHUNK;
            let hi = (lo + CHUNK).min(h.len());
            let mut a = Acc::ZERO;
            for i in lo..hi {
                a.observe_load(p[i], hmax - h[i], u[i]);
            }
            *acc = a;
        });
        combine(&self.parts)
    }

    /// Rescaled load steps (module documentation): `p ← k p` with
    /// `k = (N_c Δ − Σ_{I_c} (max h − h)) / Σ_{I_c} u`, and the gap at the same `Δ` with it,
    /// `g ← g + (k − 1) u`, where `u = g − (max h − Δ) + h` is read back from the gap (no `u`
    /// field is kept). The scaled gap has zero mean over `I_c`. Returns the reductions of the
    /// new state, or `None` (nothing changed) when `k` is not usable: no contact,
    /// `Σ_{I_c} u ≤ 0`, or `k ≤ 0`.
    pub(super) fn rescale(&mut self, delta: f64) -> Option<Acc> {
        let (h, hmax) = (self.h, self.hmax);
        let top = hmax - delta;
        let Work { p, g, parts, .. } = self;
        // Σ_{I_c} (max h − h) in `sh`, Σ_{I_c} u in `su`.
        parts
            .par_iter_mut()
            .zip(p.par_chunks(CHUNK))
            .zip(g.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(c, ((acc, pc), gc))| {
                let hc = &h[c * CHUNK..c * CHUNK + pc.len()];
                let mut a = Acc::ZERO;
                for i in 0..pc.len() {
                    a.observe_load(pc[i], hmax - hc[i], gc[i] - top + hc[i]);
                }
                *acc = a;
            });
        let now = combine(parts);
        let k = (delta * now.n_c as f64 - now.sh) / now.su;
        if !(now.n_c > 0 && now.su > 0.0 && k.is_finite() && k > 0.0) {
            return None;
        }
        parts
            .par_iter_mut()
            .zip(p.par_chunks_mut(CHUNK))
            .zip(g.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((acc, pc), gc))| {
                let hc = &h[c * CHUNK..c * CHUNK + pc.len()];
                let mut a = Acc::ZERO;
                for i in 0..pc.len() {
                    let gi = gc[i] + (k - 1.0) * (gc[i] - top + hc[i]);
                    let pi = k * pc[i];
                    gc[i] = gi;
                    pc[i] = pi;
                    a.observe(pi, gi);
                }
                *acc = a;
            });
        Some(combine(parts))
    }

    /// Step 1 from a fresh `u`: the gap (load control: with `Δ` from the mean over `I_c`).
    /// Returns the reductions and the approach.
    pub(super) fn evaluate(&mut self, mode: Mode) -> (Acc, f64) {
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

    /// Preconditioned residual `z = M (g on I_c)` restricted to `I_c`, written into `r` (zero
    /// off `I_c`; `r` is scratch between an update and the next product `C t`); returns
    /// `Σ_{I_c} g z` (in `gt`).
    pub(super) fn precondition(&mut self) -> Acc {
        // In f32 with the operator's f32 twin (the single-precision switch, module docs): an
        // approximate preconditioner changes the rate a little, not the answer. The twin is
        // built with the preconditioner (driver), so `single()` only hands it out.
        let pre = self
            .pre
            .as_ref()
            .expect("precondition() needs a preconditioner");
        let (p, g, r) = (&self.p, &self.g, &mut self.r);
        let in_contact = |v: f64| v > 0.0;
        match (self.single.is_some(), pre.single()) {
            (true, Ok(single)) => single.apply_restricted(g, p, in_contact, r),
            _ => pre.apply_restricted(g, p, in_contact, r),
        }
        self.pre_applies += 1;
        let r = &self.r;
        self.parts
            .par_iter_mut()
            .zip(g.par_chunks(CHUNK))
            .enumerate()
            .for_each(|(c, (acc, gc))| {
                let zc = &r[c * CHUNK..c * CHUNK + gc.len()];
                let mut a = Acc::ZERO;
                a.gt = gc.iter().zip(zc).fold(0.0, |s, (x, y)| s + x * y);
                *acc = a;
            });
        combine(&self.parts)
    }

    /// Step 2 with the preconditioned residual `z` (in `r`, from [`Work::precondition`]):
    /// `t = z + β t` on `I_c`, 0 elsewhere. Returns `Σ g t`, `Σ_W t`, `|W|`.
    pub(super) fn direction_preconditioned(&mut self, beta: f64) -> Acc {
        let Work {
            p, g, r, t, parts, ..
        } = self;
        let z = &*r;
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
    pub(super) fn direction(&mut self, beta: f64, steepest: bool) -> Acc {
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
    pub(super) fn curvature(&mut self, steepest: bool, with_mean: bool) -> Acc {
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
    pub(super) fn chord(&mut self, tau: f64, tau_ol: f64) -> Acc {
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
    pub(super) fn chord_update(&mut self, s: f64) -> Acc {
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

    /// The trial of a load-controlled chord step: `p(τ)` = steps 5–6 applied to `p − τ t`,
    /// scaled to the load, `p(τ) ← p(τ) · target / Σ p(τ)` (step 7), and `t ← d = p(τ) − p`,
    /// so `Σ d = 0` and the chord keeps the load. Returns `Σ g d` (in `gt`; NaN when `p(τ)`
    /// vanishes, which takes no chord step) and `n_nl` as [`Work::chord`].
    pub(super) fn chord_load(&mut self, tau: f64, tau_ol: f64, target: f64) -> Acc {
        let Work { p, g, t, parts, .. } = self;
        let first = rewrite_t(parts, t, p, g, |_, pk, gk, tk, a| {
            let lin = pk - tau * tk;
            let pn = Self::step_point(lin, gk, tau_ol, a);
            if pn != lin {
                a.n_nl += 1;
            }
            a.sum_p += pn;
            pn
        });
        if !positive(first.sum_p) {
            let mut a = first;
            a.gt = f64::NAN;
            return a;
        }
        let s = target / first.sum_p;
        let second = rewrite_t(parts, t, p, g, |_, pk, gk, tk, a| {
            let d = s * tk - pk;
            a.gt += gk * d;
            d
        });
        Acc {
            gt: second.gt,
            ..first
        }
    }

    /// The load-controlled chord step `p ← p + s d`, `u ← u + s r` with `d` in `t` and
    /// `r = C d`. Returns `|I_c|`, `Σ p`, `Σ_{I_c} (max h − h)`, `Σ_{I_c} u` of the new state
    /// (the gap is written by the following [`Work::gap_pass`]).
    pub(super) fn chord_update_load(&mut self, s: f64) -> Acc {
        let (h, hmax) = (self.h, self.hmax);
        let Work {
            p, u, t, r, parts, ..
        } = self;
        let (t, r) = (&*t, &*r);
        parts
            .par_iter_mut()
            .zip(p.par_chunks_mut(CHUNK))
            .zip(u.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(|(c, ((acc, pc), uc))| {
                let lo = c * CHUNK;
                let len = pc.len();
                let (tc, rc, hc) = (&t[lo..lo + len], &r[lo..lo + len], &h[lo..lo + len]);
                let mut a = Acc::ZERO;
                for i in 0..len {
                    if tc[i] != 0.0 {
                        pc[i] = (pc[i] + s * tc[i]).max(0.0);
                    }
                    let ui = uc[i] + s * rc[i];
                    uc[i] = ui;
                    a.observe_load(pc[i], hmax - hc[i], ui);
                }
                *acc = a;
            });
        combine(parts)
    }

    /// Largest `τ` with `p − τ t ≥ 0` (ratio test), `∞` if none limits it.
    pub(super) fn ratio_test(&mut self) -> f64 {
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
    pub(super) fn step_point(lin: f64, g: f64, tau: f64, a: &mut Acc) -> f64 {
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
    pub(super) fn update(&mut self, tau: f64, tau_ol: f64, mode: Mode) -> Acc {
        let (h, hmax) = (self.h, self.hmax);
        let n_chunks = self.parts.len();
        let Work {
            p,
            u,
            g,
            t,
            r,
            slots,
            parts,
            changes_field,
            ..
        } = self;
        let (t, r) = (&*t, &*r);
        // Each chunk's part of the changes field, when there is one.
        let fields = if changes_field.is_empty() {
            Either::Left((0..n_chunks).into_par_iter().map(|_| None))
        } else {
            Either::Right(changes_field.par_chunks_mut(CHUNK).map(Some))
        };
        match mode {
            Mode::Displacement(_) => parts
                .par_iter_mut()
                .zip(slots.par_chunks_mut(SPARSE_MAX))
                .zip(p.par_chunks_mut(CHUNK))
                .zip(g.par_chunks_mut(CHUNK))
                .zip(fields)
                .enumerate()
                .for_each(|(c, ((((acc, sl), pc), gc), mut fc))| {
                    let lo = c * CHUNK;
                    let len = pc.len();
                    let (tc, rc) = (&t[lo..lo + len], &r[lo..lo + len]);
                    let mut a = Acc::ZERO;
                    for i in 0..len {
                        let lin = pc[i] - tau * tc[i];
                        let pn = Self::step_point(lin, gc[i], tau_ol, &mut a);
                        if pn != lin {
                            record(sl, &mut a, lo + i, pn - lin);
                            if let Some(f) = fc.as_deref_mut() {
                                f[i] = pn - lin;
                            }
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
                .zip(fields)
                .enumerate()
                .for_each(|(c, ((((acc, sl), pc), uc), mut fc))| {
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
                            if let Some(f) = fc.as_deref_mut() {
                                f[i] = pn - lin;
                            }
                        }
                        pc[i] = pn;
                        let ui = uc[i] - tau * rc[i];
                        uc[i] = ui;
                        a.observe_load(pn, hmax - hc[i], ui);
                    }
                    *acc = a;
                }),
        }
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
