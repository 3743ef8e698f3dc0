"""Type stubs for leakpath's compiled Rust core (``leakpath._core``)."""

from typing import Literal as _Literal

import numpy as np
import numpy.typing as npt

__version__: str

#: ``solver="auto"`` runs the block active set on grids of at most this many points
#: (displacement control), Polonsky–Keer otherwise.
AUTO_ACTIVE_SET_MAX_POINTS: int

_F64 = npt.NDArray[np.float64]

class CoarseCost:
    """What the coarse levels of a cold Polonsky–Keer start cost (all zero without one; not
    included in the fine counts of :class:`ContactSolution`): raw counts on the coarse grids,
    and the products weighted by each grid's share of the points (``Σ count · N_level / N``)."""

    @property
    def levels(self) -> int: ...
    @property
    def iterations(self) -> int: ...
    @property
    def fft_products(self) -> int: ...
    @property
    def preconditioner_products(self) -> int: ...
    @property
    def fft_products_fine_equivalent(self) -> float: ...
    @property
    def preconditioner_products_fine_equivalent(self) -> float: ...

class ContactSolution:
    """One contact solve, whichever solver ran (read-only; the core's ``contact::Solution``
    under the same names). Grids are ``(ny, nx)`` float64; the gap is not clamped."""

    @property
    def solver(self) -> _Literal["polonsky-keer", "active-set", "lawson-hanson"]:
        """The solver that ran (``"auto"`` resolved)."""
    @property
    def pressure(self) -> _F64:
        """Contact pressure ``p ≥ 0`` [units of ``E``]."""
    @property
    def displacement(self) -> _F64:
        """``u = C p`` [length]."""
    @property
    def gap(self) -> _F64:
        """``g = max h − Δ − h + u`` [length]."""
    @property
    def approach(self) -> float:
        """``Δ`` [length]: imposed, or computed under load control."""
    @property
    def iterations(self) -> int: ...
    @property
    def fft_products(self) -> int:
        """Operator applications ``C x`` (FFT pairs of the padded grid); 0 for the exact
        solvers."""
    @property
    def single_products(self) -> int:
        """Of ``fft_products``, those made in single precision (Polonsky–Keer's iterations
        while the certificate was above ``single_precision_above``)."""
    @property
    def preconditioner_products(self) -> int:
        """Preconditioner applications (FFT pairs on the unpadded grid)."""
    @property
    def chord_steps(self) -> int:
        """Iterations taken as chord steps (included in ``iterations``)."""
    @property
    def kkt(self) -> float:
        """KKT certificate relative to the height range."""
    @property
    def contact_points(self) -> int:
        """``#(p > 0)``."""
    @property
    def plastic_points(self) -> int:
        """Points at the hardness, ``p = H`` (0 without a hardness)."""
    @property
    def load(self) -> float:
        """``F = dx² Σ p`` [pressure · length²]."""
    @property
    def mean_pressure(self) -> float:
        """``p̄ = Σ p / N`` [units of ``E``]."""
    @property
    def coarse(self) -> CoarseCost: ...
    @property
    def seconds(self) -> float:
        """Wall time of the solve [s]."""

#: A flow direction as it crosses into the core: the canonical values of
#: :func:`leakpath._validate.axis` (the flow solver takes 0 or 1 only).
Axis = _Literal[0, 1, "either", "both"]

class Labelling:
    """:func:`label_open`: the open cells of one gap labelled once (frozen; read-only arrays).

    ``labels`` (``uint32``, as :func:`label_clusters`), ``n_clusters``; per cluster (entry
    ``k − 1`` for label ``k``): ``areas`` (cells, ``uint64``), ``volumes`` (``Σ g·dx²``,
    ``float64``), ``touches`` (bit flags 1 first row, 2 last row, 4 first column, 8 last
    column, ``uint8``); and the labelling's ``connectivity``, ``periodic_axis0``,
    ``periodic_axis1`` and ``dx``.
    """

    @property
    def labels(self) -> npt.NDArray[np.uint32]: ...
    @property
    def n_clusters(self) -> int: ...
    @property
    def areas(self) -> npt.NDArray[np.uint64]: ...
    @property
    def volumes(self) -> _F64: ...
    @property
    def touches(self) -> npt.NDArray[np.uint8]: ...
    @property
    def connectivity(self) -> int: ...
    @property
    def periodic_axis0(self) -> bool: ...
    @property
    def periodic_axis1(self) -> bool: ...
    @property
    def dx(self) -> float: ...

class Classification:
    """:func:`classify`: classes of a labelling's clusters for one ``axis`` (frozen).

    ``classes`` (1 spanning, 2 dead-end, 3 trapped, ``uint8``, read-only); totals
    ``spanning_volume``, ``dead_end_volume``, ``trapped_volume``, ``free_volume``
    (compensated sums over clusters, so the three classes add up to ``free_volume`` to a few
    ulps), cell counts ``spanning_cells``, ``dead_end_cells``, ``trapped_cells``,
    ``free_cells``, and ``n_spanning``, ``n_dead_end``, ``n_trapped``.
    """

    @property
    def axis(self) -> Axis: ...
    @property
    def classes(self) -> npt.NDArray[np.uint8]: ...
    @property
    def spanning_volume(self) -> float: ...
    @property
    def dead_end_volume(self) -> float: ...
    @property
    def trapped_volume(self) -> float: ...
    @property
    def free_volume(self) -> float: ...
    @property
    def spanning_cells(self) -> int: ...
    @property
    def dead_end_cells(self) -> int: ...
    @property
    def trapped_cells(self) -> int: ...
    @property
    def free_cells(self) -> int: ...
    @property
    def n_spanning(self) -> int: ...
    @property
    def n_dead_end(self) -> int: ...
    @property
    def n_trapped(self) -> int: ...

class FlowAnalysis:
    """The sparse Cholesky factor's ordering and symbolic analysis, kept from one
    :func:`solve_reynolds_flow` call to the next (docs/flow.md, "Reuse across a sweep").

    A call given ``analysis`` on a grid of at least ``min_cells`` cells factors on the kept
    analysis when the grid and wrap match and its unknowns are among the analysis's and at
    least 95 % of them (cells that closed get identity rows); otherwise it analyses afresh
    and keeps the new analysis. The rate differs from a fresh analysis's by round-off only.
    Never saved or pickled; thread-safe.
    """

    def __init__(self, min_cells: int = 1048576) -> None: ...
    @property
    def analyses(self) -> int:
        """Calls that made a new analysis."""
    @property
    def reuses(self) -> int:
        """Calls that factored on the kept analysis."""
    @property
    def unknowns(self) -> int:
        """Unknowns of the kept analysis (0 without one)."""
    @property
    def entries(self) -> int:
        """Entries of a factor on the kept analysis (0 without one)."""
    def clear(self) -> None:
        """Drops the kept analysis (its memory); the counts stay."""

class FlowSolution:
    """:func:`solve_reynolds_flow` (frozen): the fields and integrals of one flow solve."""

    @property
    def pressure(self) -> _F64: ...
    @property
    def flux_axis0(self) -> _F64: ...
    @property
    def flux_axis1(self) -> _F64: ...
    @property
    def flow_rate(self) -> float: ...
    @property
    def inlet_flow_rate(self) -> float: ...
    @property
    def conductance(self) -> float: ...
    @property
    def permeability(self) -> float: ...
    @property
    def residual(self) -> float: ...
    @property
    def conservation(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def n_unknowns(self) -> int: ...
    @property
    def levels(self) -> int: ...
    @property
    def solver(self) -> str: ...
    @property
    def seconds(self) -> float: ...
    @property
    def labelled(self) -> bool:
        """True when the solve labelled the open cells itself (no ``labels`` given)."""

def elementary(
    values: npt.NDArray[np.float64],
    function: _Literal["power", "exp", "log", "log10", "cbrt"],
    exponent: float | None = None,
) -> npt.NDArray[np.float64]:
    """``function`` of every value of a contiguous 1-D float64 array (``"power"``: ``x**exponent``),
    each by one scalar function whatever the CPU (the C library's ``pow``, ``exp``, ``log``,
    ``log10``; leakpath's own ``cbrt``): the same bits on every CPU, where numpy's own loops
    use SVML on CPUs with AVX-512. A new array.
    ``InvalidArgumentError`` (``function``) for another name, or an exponent given with a
    function other than ``"power"`` (or missing with it)."""

def kernel_table(
    ny: int, nx: int, dx: float, e_star: float, memory_limit: int | None = None
) -> npt.NDArray[np.float64]:
    """Love influence table ``K[|di|, |dj|]``, shape ``(ny, nx)``.

    Displacement at the centre of an element ``di`` rows and ``dj`` columns away from a
    ``dx × dx`` element under unit uniform pressure, on a half-space of contact modulus
    ``e_star``. ``K[0, 0] = 4·dx·ln(1 + √2)/(π E*)``; far away ``K → dx²/(π E* r)``.
    ``ProblemTooLargeError`` before allocating when ``8·ny·nx`` bytes exceed ``memory_limit``
    (default :func:`leakpath._memory.memory_limit`) or overflow.
    """

class ContactProblem:
    """An elastic rough surface against a rigid flat: Love kernel, FFT operator and the
    Lawson–Hanson Cholesky factor, kept across solves (gap ``g = max h − Δ − h + C p``)."""

    def __init__(
        self,
        heights: npt.NDArray[np.float64],
        dx: float,
        e_star: float,
        boundary: str = "free",
        memory_limit: int | None = None,
    ) -> None:
        """``memory_limit`` (bytes): default :func:`leakpath._memory.memory_limit`; bounds
        the operator and the growing Cholesky factor (``ProblemTooLargeError`` beyond it)."""
    @property
    def n_passive(self) -> int:
        """Points in the contact (passive) set kept from the last solve."""
    def apply(self, pressure: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Displacement ``u = C p`` by FFT, shape ``(ny, nx)``."""
    def block(self, indices: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
        """Dense block ``C_PP`` for flat indices (free-boundary Love coefficients)."""
    def solve(
        self,
        approach: float | None = None,
        mean_pressure: float | None = None,
        solver: _Literal["auto", "polonsky-keer", "active-set", "lawson-hanson"] = "auto",
        start: _Literal["cold", "previous", "pressure", "set"] = "cold",
        initial_pressure: npt.NDArray[np.float64] | None = None,
        contact_set: npt.NDArray[np.int64] | None = None,
        tol: float = 1e-12,
        max_iter: int | None = None,
        threads: int | None = None,
        precondition: bool = True,
        coarse_start: bool = True,
        chord_steps: bool = True,
        rescaled_steps: bool = True,
        hardness: float | None = None,
        single_precision_above: float = 1e-4,
    ) -> ContactSolution:
        """Solve at ``approach`` or at ``mean_pressure`` (exactly one; the exact solvers take
        the approach only). ``start``: ``"cold"`` (p = 0), ``"previous"`` (this problem's
        last solve: Polonsky–Keer from its pressure, the exact solvers from their kept
        passive set), ``"pressure"`` with ``initial_pressure`` (the exact solvers start from
        its support ``p > 0``) or ``"set"`` with ``contact_set`` (flat indices; Polonsky–Keer
        starts cold). ``"auto"`` runs the block active set on grids of at most
        :data:`AUTO_ACTIVE_SET_MAX_POINTS` points in displacement control, Polonsky–Keer
        otherwise; ``solver`` in the result names the one that ran. ``threads``: run on a
        pool of that many threads (1: the calling thread's own one-thread pool; default: the
        solver pool); the result does not depend on it.

        Polonsky–Keer finds ``p ≥ 0`` with ``g ≥ 0``, ``p·g = 0`` by constrained conjugate
        gradients on the FFT operator. Displacement control fixes ``Δ ≥ 0`` (periodic:
        ``Δ ≤ max h − mean h``, where full contact is reached: at the limit the full-contact
        state with ``min p = 0`` is returned, beyond it ``ValueError``); load control fixes
        ``p̄ > 0`` (``F = p̄·A0``) and returns ``Δ = mean over the contact set of
        (max h − h + u)``. ``tol``: stop when the KKT certificate
        ``max(−min g, max_{p>0} |g|, Σ p|g| / Σ p) / (max h − min h)`` is ``≤ tol``.
        ``max_iter``: default ``max(5000, ⌈100·N^¼⌉)`` (Polonsky–Keer), ``50 N + 1000``
        (exact solvers); exceeding it raises ``RuntimeError``. Four settings tune
        Polonsky–Keer and leave the answer the same minimiser: ``precondition`` (conjugate
        steps preconditioned with the inverse half-space compliance ``E*|q|/2`` on the
        contact set), ``coarse_start`` (a cold solve on a grid of at least 64 points per side
        starts from the solution on the grid coarsened by two, at most two levels deep, to KKT
        ``1e-2``, prolonged bilinearly), ``chord_steps`` (while an
        iteration truncates or adds more than 2 % of the contact set, the next one is a
        chord step with one FFT product of the whole change and an exact line search) and
        ``rescaled_steps`` (displacement control of a free surface from a start with
        pressure, coarse or the caller's: each step is taken as under load control at the
        current load, then ``p`` is scaled so that the gap at the imposed ``Δ`` has zero mean
        over the contact set; periodic surfaces always take the plain steps).
        ``single_precision_above``: while the certificate is above this level the FFT
        products are made in single precision (relative error ~1e-7); below it the full
        products ``u = C p`` are double precision (at the switch, at every hundredfold fall
        of the certificate and to confirm convergence) and the increments (``C t``, and
        ``C d`` of chord steps and of steps that change many points) stay single, so the
        returned fields and the certificate are double precision; with it,
        the preconditioner's products are single precision too; ``0`` turns it off.
        ``ProblemTooLargeError`` (a ``MemoryError``) up front when the solve would need more
        than the problem's ``memory_limit``. The GIL is released; Ctrl-C raises
        ``KeyboardInterrupt`` within a fraction of a second.

        ``hardness``: cap the pressure at ``p ≤ H`` (elastic–perfectly-plastic contact,
        ``docs/plasticity.md``; Polonsky–Keer only, ``"auto"`` resolves to it, the exact
        solvers are refused): points at ``p = H`` may have ``g < 0`` (plastic
        interpenetration), ``plastic_points`` counts them. The chord steps are not used then;
        the preconditioner (on ``0 < p < H``) and the coarse start are kept. Load control requires
        ``mean_pressure ≤ hardness``. ``None``/``inf``: the elastic solve, bit for bit."""

# ---- clusters ----
def label_clusters(
    free: npt.NDArray[np.bool_],
    connectivity: int = 4,
    periodic_axis0: bool = False,
    periodic_axis1: bool = False,
    threads: int | None = None,
) -> tuple[npt.NDArray[np.uint32], int]:
    """Connected components of a free mask (``True`` = free), 2-D.

    Returns ``(labels, K)``: ``uint32`` labels of the mask's shape, 0 on non-free cells and
    ``1..K`` on free cells in raster order of each cluster's first cell. ``connectivity`` 4
    (edge neighbours) or 8 (edges and corners); ``periodic_axis0``/``periodic_axis1`` make the
    first and last row/column neighbours. ``threads``: rayon threads (default all cores; at
    most four per available core); the result does not depend on it. The GIL is released;
    Ctrl-C raises ``KeyboardInterrupt``. Bad arguments raise ``ValueError``.
    """

def label_open(
    gap: npt.NDArray[np.float64],
    dx: float,
    contact: npt.NDArray[np.bool_] | None = None,
    connectivity: int = 4,
    periodic_axis0: bool = False,
    periodic_axis1: bool = False,
    threads: int | None = None,
) -> Labelling:
    """Labels the open cells of a gap once: not in contact and ``g > 0`` (no contact mask:
    ``g > 0``), the one rule the flow uses too. ``gap`` must be finite everywhere; ``dx > 0``.
    Per-cluster cells, volumes and touch flags come with the labels (:class:`Labelling`).
    """

def classify(
    labelling: Labelling, axes: list[Axis], threads: int | None = None
) -> list[Classification]:
    """Percolation classes of a labelling's clusters for flow along each of ``axes`` (0, 1,
    ``"either"`` or ``"both"``), one :class:`Classification` per axis in order: per-cluster
    work only, no labelling. Wrap along a flow axis is a ``ValueError`` (a periodic surface
    wraps across the flow)."""

def free_gap_extremes(
    gap: npt.NDArray[np.float64], contact: npt.NDArray[np.bool_] | None = None
) -> tuple[float, float]:
    """``(min, max)`` of ``gap`` over the cells where ``contact`` is False (every cell
    without a mask), ``(inf, -inf)`` when none is free; one parallel pass. The values are
    expected finite (NaN is skipped). ``contact`` of another shape is refused naming it."""

def solve_reynolds_flow(
    gap: npt.NDArray[np.float64],
    dx: float,
    contact: npt.NDArray[np.bool_] | None = None,
    axis: int = 0,
    viscosity: float = 1.0,
    pressure_drop: float = 1.0,
    periodic: bool = False,
    tol: float = 1e-12,
    max_iter: int | None = None,
    memory_limit: int | None = None,
    solver: _Literal["auto", "cholesky", "multigrid"] = "auto",
    threads: int | None = None,
    labels: Labelling | None = None,
    analysis: FlowAnalysis | None = None,
) -> FlowSolution:
    """Steady Reynolds flow ``∇·(g³/(12η) ∇p) = 0`` through the gap (docs/flow.md).

    Cell-centred finite volumes, harmonic-mean faces, reservoirs at ``pressure_drop`` (inlet,
    before the first index along ``axis``) and 0 (outlet) half a cell from the boundary
    cells; no-flux side walls, or wrap across the flow with ``periodic``. Open cells: not in
    ``contact`` and ``g > 0`` (as :func:`label_open`). ``labels``: a :class:`Labelling` of
    these open cells with connectivity 4 and the flow's wrap, used instead of labelling
    again (``ValueError`` naming ``labels`` otherwise). ``axis``: 0 or 1. ``solver``:
    "cholesky" (sparse Cholesky, refined with double-double residuals), "multigrid"
    (conjugate gradients with a classical (Ruge–Stüben) algebraic multigrid preconditioner to
    ``‖b − Ax‖/‖b‖ ≤ tol`` and ``|Q_in − Q_out| ≤ tol·|Q_out|`` unless round-off stalls it
    first) or "auto" (Cholesky whenever its factor fits in
    ``memory_limit`` and the available memory and is not predicted slower than the
    multigrid, multigrid otherwise; the multigrid from 2^22 unknowns; docs/flow.md). Returns a
    :class:`FlowSolution`: ``pressure`` (ny, nx; NaN on closed cells and on clusters joined to no
    reservoir), ``flux_axis0`` (ny + 1, nx),
    ``flux_axis1`` (ny, nx + 1) (volume per time through each face, positive towards
    increasing index), ``flow_rate`` (outlet), ``inlet_flow_rate``, ``conductance``
    (``Q/Δp``), ``permeability`` (``Q η L/(W Δp)``), ``residual``, ``conservation``
    (largest net cell flux / Q), ``iterations``,
    ``n_unknowns``, ``levels``, ``solver`` (the one that ran: "cholesky", "multigrid" or
    "none" when nothing spans), ``seconds``, ``labelled``. ``InvalidArgumentError`` for bad input,
    ``NotConvergedError`` past ``max_iter`` (default 20000), ``ProblemTooLargeError`` above
    ``memory_limit`` bytes. ``threads``: run on a kept pool of that many threads (default:
    the solver pool, all cores); the result does not depend on it. ``analysis``: a
    :class:`FlowAnalysis` whose kept factor analysis is used when it fits (and replaced when
    not); the rate then differs from a fresh analysis's by round-off only. The GIL is released;
    Ctrl-C raises ``KeyboardInterrupt``.
    """

def solver_threads() -> int:
    """Threads of the pool the solvers run on: all cores, or ``RAYON_NUM_THREADS``."""

def dense_scratch_bytes() -> int:
    """Bytes of the packing scratch the dense matrix products (active-set Cholesky updates,
    the flow's sparse factor) allocate once per thread: twice the last-level cache this CPU
    reports. Checked with a fallible reservation before a thread's first such product."""
