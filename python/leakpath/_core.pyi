"""Type stubs for leakpath's compiled Rust core (``leakpath._core``)."""

from typing import Literal as _Literal
from typing import TypedDict as _TypedDict

import numpy as np
import numpy.typing as npt

__version__: str

#: ``solver="auto"`` runs the block active set on grids of at most this many points
#: (displacement control), Polonsky–Keer otherwise.
AUTO_ACTIVE_SET_MAX_POINTS: int

_F64 = npt.NDArray[np.float64]

class _SolveFields(_TypedDict):
    """The fields every contact solve returns. The same field has the same name in every
    result: ``contact_points`` is ``#(p > 0)``, ``applies`` the FFT products. ``coarse_*``: the
    coarse-to-fine start of a cold Polonsky–Keer solve (raw counts on the coarse grids, and
    their sum weighted by each grid's share of the points); zero otherwise."""

    pressure: _F64
    displacement: _F64
    gap: _F64
    approach: float
    iterations: int
    applies: int
    preconditioner_applies: int
    coarse_levels: int
    coarse_iterations: int
    coarse_applies: int
    coarse_preconditioner_applies: int
    coarse_applies_fine_equivalent: float
    coarse_preconditioner_fine_equivalent: float
    kkt: float
    contact_points: int
    #: Points at the hardness (``p = H``); 0 without a hardness.
    plastic_points: int
    seconds: float

class ContactResult(_SolveFields):
    """One contact solve, whichever solver ran: the common fields and the solver that ran."""

    solver: _Literal["polonsky-keer", "active-set", "lawson-hanson"]

class PolonskyKeerResult(_SolveFields):
    """:func:`solve_polonsky_keer`: the common fields plus the load, and how many of the
    iterations were chord steps (each one product of the whole pressure change)."""

    load: float
    mean_pressure: float
    chord_steps: int

class ClusterResult(_TypedDict):
    """:func:`classify_clusters`."""

    labels: npt.NDArray[np.uint32]
    n_clusters: int
    areas: npt.NDArray[np.uint64]
    volumes: _F64
    touches: npt.NDArray[np.uint8]
    classes: npt.NDArray[np.uint8]
    spanning_volume: float
    dead_end_volume: float
    trapped_volume: float
    free_volume: float
    spanning_area: int
    dead_end_area: int
    trapped_area: int
    free_area: int
    n_spanning: int
    n_dead_end: int
    n_trapped: int

class FlowResult(_TypedDict):
    """:func:`solve_reynolds_flow`."""

    pressure: _F64
    flux_axis0: _F64
    flux_axis1: _F64
    flow_rate: float
    inlet_flow_rate: float
    conductance: float
    permeability: float
    residual: float
    conservation: float
    iterations: int
    n_unknowns: int
    levels: int
    solver: str
    seconds: float

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

# ---- polonsky-keer ----
def solve_polonsky_keer(
    heights: npt.NDArray[np.float64],
    dx: float,
    e_star: float,
    boundary: _Literal["free", "periodic"] = "free",
    approach: float | None = None,
    mean_pressure: float | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    initial_pressure: npt.NDArray[np.float64] | None = None,
    memory_limit: int | None = None,
    precondition: bool = True,
    operator_of: ContactProblem | None = None,
    coarse_start: bool = True,
    chord_steps: bool = True,
    hardness: float | None = None,
) -> PolonskyKeerResult:
    """Normal contact of an elastic rough surface against a rigid flat, Polonsky–Keer CG.

    Finds ``p ≥ 0`` with gap ``g = max(h) − Δ − h + u ≥ 0``, ``p·g = 0``, ``u = C p`` (FFT
    influence operator, ``boundary`` "free" or "periodic"). Give exactly one of

    - ``approach`` ``Δ ≥ 0`` (displacement control; periodic: ``Δ ≤ max h − mean h``, where
      full contact is reached — at the limit the full-contact state with ``min p = 0`` is
      returned, beyond it ``ValueError``), or
    - ``mean_pressure`` ``p̄ > 0`` (load control, ``F = p̄·A0``, ``A0 = ny·nx·dx²``); the
      returned approach is ``Δ = mean over the contact set of (max h − h + u)``, positive when
      the flat has moved down from first touch.

    ``heights``: float64 array ``(ny, nx)``, finite. ``tol``: stop when the KKT certificate
    ``max(−min g, max_{p>0} |g|, Σ p|g| / Σ p) / (max h − min h)`` is ``≤ tol`` (default
    ``1e-12``). ``max_iter``: default ``max(5000, ⌈100·N^¼⌉)``; exceeding it raises
    ``RuntimeError``. ``initial_pressure``: warm start (same shape; negatives clipped; rescaled
    to the load in load control); cold start is ``p = 0`` (displacement) or uniform ``p̄``
    (load). ``memory_limit`` (bytes, default :func:`leakpath._memory.memory_limit`):
    ``ProblemTooLargeError`` (a ``MemoryError``) up front when the solve would need more, or
    when an allocation fails. The GIL is released; Ctrl-C raises ``KeyboardInterrupt`` within
    a fraction of a second. ``precondition``: FFT-preconditioned conjugate steps (inverse
    half-space compliance ``E*|q|/2`` on the contact set). ``operator_of``: reuse the operator
    of a :class:`ContactProblem` of the same grid. ``coarse_start``: a cold solve (no
    ``initial_pressure``) on a grid of at least 64 points per side starts from the solution on
    the grid coarsened by two (every other node, ``2·dx``, solved the same way, at most two
    levels deep and not below 64 points per side, to KKT ``1e-2``), prolonged bilinearly; the
    answer is the same minimiser. ``chord_steps`` (displacement control): while an iteration
    truncates or adds more than 0.5 % of the contact set, the next one is a chord step (the
    projected trial step's whole change gets one FFT product and an exact line search on the
    chord) instead of a conjugate step followed by a fresh product; ``False`` keeps every
    iteration a regular Polonsky–Keer step. The answer is the same minimiser.

    Returns a dict: ``pressure``, ``displacement``, ``gap`` (``(ny, nx)`` float64; the gap is
    not clamped), ``approach``, ``iterations`` (CG steps), ``applies`` (FFT convolutions),
    ``preconditioner_applies``, ``chord_steps`` (iterations taken as chord steps), ``kkt``,
    ``load`` (``F = dx² Σ p``), ``mean_pressure``,
    ``contact_points`` (``#(p > 0)``), ``seconds``, and the cost of the coarse levels (0
    without a coarse start; not included in the counts above): ``coarse_levels``,
    ``coarse_iterations``, ``coarse_applies``, ``coarse_preconditioner_applies`` (raw, each
    on its own grid), ``coarse_applies_fine_equivalent``,
    ``coarse_preconditioner_fine_equivalent`` (``Σ count · N_level / N``).

    ``hardness``: cap the pressure at ``p ≤ H`` (elastic–perfectly-plastic contact,
    ``docs/plasticity.md``): points at ``p = H`` may have ``g < 0`` (plastic
    interpenetration), ``plastic_points`` counts them. The preconditioner and chord steps are
    not used then (``precondition``/``chord_steps`` are ignored); the coarse start is kept.
    Load control requires ``mean_pressure ≤ hardness``. ``None``/``inf``: the elastic solve.
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
    def resolve_solver(
        self, solver: str = "auto", load_control: bool = False, hardness: float | None = None
    ) -> str:
        """The solver ``solver`` runs on this grid (the ``auto`` policy; with a finite
        ``hardness`` always Polonsky–Keer, the exact solvers are refused)."""
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
        hardness: float | None = None,
    ) -> ContactResult:
        """Solve at ``approach`` or at ``mean_pressure`` (exactly one; the exact solvers take
        the approach only). ``start``: ``"cold"`` (p = 0), ``"previous"`` (this problem's
        last solve: Polonsky–Keer from its pressure, the exact solvers from their kept
        passive set), ``"pressure"`` with ``initial_pressure`` (the exact solvers start from
        its support ``p > 0``) or ``"set"`` with ``contact_set`` (flat indices; Polonsky–Keer
        starts cold). ``"auto"`` runs the block active set on grids of at most
        :data:`AUTO_ACTIVE_SET_MAX_POINTS` points in displacement control, Polonsky–Keer
        otherwise; ``solver`` in the result names the one that ran. ``threads``: run on a
        pool of that many threads (1: the calling thread's own one-thread pool; default: the
        solver pool); the result does not depend on it. ``hardness``: cap the pressure at
        ``p ≤ H`` (elastic–perfectly-plastic; Polonsky–Keer only, ``"auto"`` resolves to it;
        ``None``/``inf``: the elastic solve, bit for bit)."""

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

def classify_clusters(
    gap: npt.NDArray[np.float64],
    dx: float,
    contact: npt.NDArray[np.bool_] | None = None,
    connectivity: int = 4,
    periodic_axis0: bool = False,
    periodic_axis1: bool = False,
    flow: str = "0",
    threads: int | None = None,
) -> ClusterResult:
    """Labels the free region and classifies its clusters for flow along ``flow``.

    Free cells are ``~contact`` when a contact mask is given, else ``gap > 0``. ``gap`` must be
    finite everywhere; ``dx > 0``. ``flow``: ``"0"``, ``"1"``, ``"either"`` or ``"both"``; wrap
    along a flow axis is a ``ValueError`` (a periodic surface wraps across the flow).

    Keys: ``labels`` (``uint32``, as :func:`label_clusters`), ``n_clusters``; per cluster
    (entry ``k − 1`` for label ``k``): ``areas`` (cells, ``uint64``), ``volumes``
    (``Σ g·dx²``, ``float64``), ``touches`` (bit flags 1 first row, 2 last row, 4 first column,
    8 last column, ``uint8``), ``classes`` (1 spanning, 2 dead-end, 3 trapped, ``uint8``);
    totals ``spanning_volume``, ``dead_end_volume``, ``trapped_volume``, ``free_volume``
    (compensated sums over clusters, so the three classes add up to ``free_volume`` to a few
    ulps), ``spanning_area``, ``dead_end_area``, ``trapped_area``, ``free_area`` (cells),
    ``n_spanning``, ``n_dead_end``, ``n_trapped``.
    """

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
) -> FlowResult:
    """Steady Reynolds flow ``∇·(g³/(12η) ∇p) = 0`` through the gap (docs/flow.md).

    Cell-centred finite volumes, harmonic-mean faces, reservoirs at ``pressure_drop`` (inlet,
    before the first index along ``axis``) and 0 (outlet) half a cell from the boundary
    cells; no-flux side walls, or wrap across the flow with ``periodic``. Closed cells:
    ``contact`` where given, else ``gap ≤ 0``. ``solver``: "cholesky" (sparse Cholesky, refined
    with double-double residuals), "multigrid" (conjugate gradients with an aggregation
    multigrid preconditioner to ``‖b − Ax‖/‖b‖ ≤ tol`` and ``|Q_in − Q_out| ≤ tol·|Q_out|``
    unless round-off stalls it first) or "auto" (Cholesky whenever its factor fits in
    ``memory_limit`` and the available memory, multigrid otherwise). Returns a
    dict: ``pressure`` (ny, nx; NaN on closed cells and on clusters joined to no
    reservoir), ``flux_axis0`` (ny + 1, nx),
    ``flux_axis1`` (ny, nx + 1) (volume per time through each face, positive towards
    increasing index), ``flow_rate`` (outlet), ``inlet_flow_rate``, ``conductance``
    (``Q/Δp``), ``permeability`` (``Q η L/(W Δp)``), ``residual``, ``conservation``
    (largest net cell flux / Q), ``iterations``,
    ``n_unknowns``, ``levels``, ``solver`` (the one that ran: "cholesky", "multigrid" or
    "none" when nothing spans), ``seconds``. ``InvalidArgumentError`` for bad input,
    ``NotConvergedError`` past ``max_iter`` (default 20000), ``ProblemTooLargeError`` above
    ``memory_limit`` bytes. ``threads``: run on a kept pool of that many threads (default:
    the solver pool, all cores); the result does not depend on it. The GIL is released;
    Ctrl-C raises ``KeyboardInterrupt``.
    """

def solver_threads() -> int:
    """Threads of the pool the solvers run on: all cores, or ``RAYON_NUM_THREADS``."""

def dense_scratch_bytes() -> int:
    """Bytes of the packing scratch the dense matrix products (active-set Cholesky updates,
    the flow's sparse factor) allocate once per thread: twice the last-level cache this CPU
    reports. Checked with a fallible reservation before a thread's first such product."""
