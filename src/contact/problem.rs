//! What a contact solve is asked and what it answers, for every solver: the surface and the
//! elastic model ([`Problem`]), what is imposed ([`Control`]), which solver runs ([`Solver`],
//! with the `auto` policy), where it starts ([`Start`]), its settings ([`Options`]) and the one
//! [`Solution`] type every solver returns. [`crate::contact::ContactProblem`] owns the
//! operators and dispatches; the solvers read these types and nothing above them.

use crate::error::{Error, Result};
use crate::grid::Boundary;

/// Default KKT tolerance, relative to the height range.
pub const DEFAULT_TOL: f64 = 1e-12;
/// Default of [`Options::single_precision_above`]: Polonsky–Keer's FFT products are all made
/// in single precision while its certificate is above this level, and only its increments
/// below it.
pub const DEFAULT_SINGLE_PRECISION_ABOVE: f64 = 1e-4;

/// `Solver::Auto` uses the exact block active set on grids of at most this many points and
/// Polonsky–Keer above. Measured from p = 0 at Δ = 0.3/0.6/1.0 h_s on an idle machine
/// (`benchmarks/auto_policy_bench.py` → `benchmarks/results/auto_policy.md`): on 17² the
/// active set is faster at every approach (0.2–0.4 ms); on 33²–65² it is faster at low
/// contact by at most 3 ms and 2–2.5× slower at half contact; from 129² on Polonsky–Keer is
/// faster at every approach, 45× at Δ = 0.6 h_s and hundreds of times at Δ = h_s (the factor
/// work grows like k³ in the contact points k, Polonsky–Keer like N log N per iteration). A
/// rule by grid size keeps one solver per grid, which warm-started sweeps need (pressure
/// fields versus contact sets); a per-solve contact-count model would save at most a few
/// milliseconds per solve on the small grids.
pub const AUTO_ACTIVE_SET_MAX_POINTS: usize = 32 * 32;

/// Which solver runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// [`Solver::ActiveSet`] on grids of at most [`AUTO_ACTIVE_SET_MAX_POINTS`] points in
    /// displacement control, [`Solver::PolonskyKeer`] otherwise.
    Auto,
    /// Constrained conjugate gradients on the FFT operator (either control).
    PolonskyKeer,
    /// Lawson–Hanson with blocks of points entering at once (displacement control).
    ActiveSet,
    /// The paper's Lawson–Hanson, one point entering per iteration (displacement control).
    LawsonHanson,
}

impl Solver {
    /// The name used by the Python API.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Auto => "auto",
            Solver::PolonskyKeer => "polonsky-keer",
            Solver::ActiveSet => "active-set",
            Solver::LawsonHanson => "lawson-hanson",
        }
    }

    /// Parse a Python-API name.
    pub fn from_name(name: &str) -> Result<Solver> {
        match name {
            "auto" => Ok(Solver::Auto),
            "polonsky-keer" => Ok(Solver::PolonskyKeer),
            "active-set" => Ok(Solver::ActiveSet),
            "lawson-hanson" => Ok(Solver::LawsonHanson),
            other => Err(Error::invalid(
                "solver",
                format!(
                    "must be 'auto', 'polonsky-keer', 'active-set' or 'lawson-hanson', got \
                     {other:?}"
                ),
            )),
        }
    }

    /// The solver that runs for `self` on a grid of `n_points` under `control` (the `auto`
    /// policy); an exact solver under load control, or with a finite `hardness`, is refused.
    pub fn resolve(
        self,
        n_points: usize,
        control: Control,
        hardness: Option<f64>,
    ) -> Result<Solver> {
        if hardness.is_some_and(f64::is_finite) {
            return match self {
                Solver::Auto | Solver::PolonskyKeer => Ok(Solver::PolonskyKeer),
                other => Err(Error::invalid(
                    "solver",
                    format!(
                        "{:?} cannot cap the pressure at a hardness; use solver='auto' or \
                         'polonsky-keer' with hardness=",
                        other.name()
                    ),
                )),
            };
        }
        match (self, control) {
            (Solver::Auto, Control::MeanPressure(_)) => Ok(Solver::PolonskyKeer),
            (Solver::Auto, Control::Approach(_)) => Ok(if n_points <= AUTO_ACTIVE_SET_MAX_POINTS {
                Solver::ActiveSet
            } else {
                Solver::PolonskyKeer
            }),
            (Solver::ActiveSet | Solver::LawsonHanson, Control::MeanPressure(_)) => {
                Err(Error::invalid(
                    "solver",
                    format!(
                        "{:?} imposes the approach only; use solver='auto' or 'polonsky-keer' \
                         with mean_pressure=",
                        self.name()
                    ),
                ))
            }
            (s, _) => Ok(s),
        }
    }
}

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

/// Where a solve starts.
#[derive(Clone, Copy, Debug)]
pub enum Start<'a> {
    /// `p = 0` (the paper: "without warm starting").
    Cold,
    /// This problem's previous solve: Polonsky–Keer from its pressure, the exact solvers from
    /// the passive set of their factor. Cold when there was none.
    Previous,
    /// A pressure field (`ny × nx`): Polonsky–Keer from it, the exact solvers from its support
    /// `{p > 0}`.
    Pressure(&'a [f64]),
    /// A contact set (flat indices): the exact solvers from it; Polonsky–Keer cold.
    ContactSet(&'a [usize]),
}

/// Settings of a solve (every solver reads `tol`, `max_iter`, `memory_limit`, `should_stop`;
/// the last three tune Polonsky–Keer and leave its answer the same minimiser).
#[derive(Clone, Copy)]
pub struct Options<'a> {
    /// Stop when the KKT certificate (relative to `h_s`) is `≤ tol`.
    pub tol: f64,
    /// Iteration cap; `None` → the solver's default (Polonsky–Keer
    /// [`crate::contact::polonsky_keer::default_max_iter`], Lawson–Hanson `50 N + 1000`).
    pub max_iter: Option<usize>,
    /// Refuse up front with [`crate::error::Error::TooLarge`] when [`crate::elastic::memory::polonsky_keer`] exceeds this (bytes).
    pub memory_limit: Option<u64>,
    /// Polled every ~10 iterations (and at least every 0.25 s); `true` → [`crate::error::Error::Interrupted`].
    pub should_stop: Option<&'a (dyn Fn() -> bool + Sync)>,
    /// Precondition the conjugate directions with the periodic inverse compliance
    /// `E*|q|/2` restricted to the contact set (see the module documentation).
    pub precondition: bool,
    /// Start a cold solve from the solution on the grid coarsened by two, recursively
    /// ([`crate::contact::polonsky_keer`]'s coarse levels); ignored with a warm start and on
    /// grids smaller than [`crate::contact::polonsky_keer::COARSE_START_MIN_SIDE`] per side.
    pub coarse_start: bool,
    /// Take chord steps while the contact set changes wholesale (both controls, see
    /// the module documentation); `false` keeps every iteration a regular Polonsky–Keer step.
    pub chord_steps: bool,
    /// Displacement control of a free surface from a start with pressure (the coarse start's
    /// or a caller's): take each step as under load control at the current load `Σ p`, then
    /// scale `p` so that the gap at the imposed approach has zero mean over the contact set
    /// ([`crate::contact::polonsky_keer`], "Rescaled load steps"); `false` keeps the plain
    /// displacement-controlled steps. Periodic surfaces always take the plain steps.
    pub rescaled_steps: bool,
    /// Hardness `H`: cap the pressure at `p ≤ H` (elastic–perfectly-plastic contact, solved by
    /// [`crate::contact::capped`]). `None` or `+∞`: the elastic problem, by the
    /// Polonsky–Keer iteration unchanged. Polonsky–Keer only ([`Solver::resolve`]).
    pub hardness: Option<f64>,
    /// Polonsky–Keer: while the certificate is above this level, the FFT products are made in
    /// single precision ([`crate::elastic::transform::Operator32`]); below it, the full
    /// products `u = C p` are made in double precision (one at the switch, then one each
    /// time the certificate has fallen a hundredfold, and one to confirm convergence) and
    /// the increments (`C t`, and `C d` of chord steps and of steps that change many points)
    /// stay single. `0` (or any level `≤ tol`): double precision
    /// throughout. The answer is the same to the certificate.
    pub single_precision_above: f64,
}

impl Default for Options<'_> {
    fn default() -> Self {
        Options {
            tol: DEFAULT_TOL,
            max_iter: None,
            memory_limit: None,
            should_stop: None,
            precondition: true,
            coarse_start: true,
            chord_steps: true,
            rescaled_steps: true,
            hardness: None,
            single_precision_above: DEFAULT_SINGLE_PRECISION_ABOVE,
        }
    }
}

/// What the coarse levels cost, summed over all of them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CoarseCost {
    /// Levels solved below the fine grid.
    pub levels: usize,
    /// Polonsky–Keer iterations on the coarse levels.
    pub iterations: usize,
    /// Operator applications on the coarse levels (raw count, each on its own grid).
    pub fft_products: usize,
    /// Preconditioner applications on the coarse levels (raw count).
    pub preconditioner_products: usize,
    /// `Σ fft_products · N_level / N_fine`: the coarse products in units of one fine product.
    pub fft_products_fine_equivalent: f64,
    /// The same for the preconditioner applications.
    pub preconditioner_products_fine_equivalent: f64,
}

/// A converged contact state, whichever solver produced it.
#[derive(Clone, Debug)]
pub struct Solution {
    /// The solver that ran ([`Solver::Auto`] resolved).
    pub solver: Solver,
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
    /// table was at hand; 0 for the exact solvers.
    pub fft_products: usize,
    /// Of `fft_products`, those made in single precision (Polonsky–Keer's early iterations,
    /// [`Options::single_precision_above`]).
    pub single_products: usize,
    /// Preconditioner applications (FFT pairs on the unpadded `ny × nx` grid), one per
    /// preconditioned iteration; 0 for the exact solvers.
    pub preconditioner_products: usize,
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
    /// `iterations`, `fft_products`, `preconditioner_products`.
    pub coarse: CoarseCost,
}
