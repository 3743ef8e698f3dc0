"""Connected components of the free region and their percolation classes.

Oracles: ``scipy.ndimage.label`` for the partition into clusters, a plain breadth-first search
(written here) for periodic wrap, and hand-made geometries whose classes are known by
construction.
"""

from __future__ import annotations

from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest

ndimage = pytest.importorskip("scipy.ndimage")

from leakpath import _core  # noqa: E402
from leakpath._percolation import (  # noqa: E402
    CLASS_NAMES,
    DEAD_END,
    SPANNING,
    TRAPPED,
    Percolation,
    percolation,
)

FOUR = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=bool)
EIGHT = np.ones((3, 3), dtype=bool)


# ---------------------------------------------------------------------------------------------
# helpers


def same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """True when two label arrays (0 = background) define the same clusters."""
    if a.shape != b.shape or not np.array_equal(a == 0, b == 0):
        return False
    fa, fb = a[a > 0].astype(np.int64), b[b > 0].astype(np.int64)
    na, nb = len(np.unique(fa)), len(np.unique(fb))
    # A bijection between the labels: each (a, b) pair is unique to its a and to its b.
    pairs = len(np.unique(fa * (int(fb.max(initial=0)) + 1) + fb))
    return na == nb == pairs


def raster_numbered(labels: np.ndarray, n: int) -> bool:
    """Labels are exactly 1..n, numbered in raster order of each cluster's first cell."""
    flat = labels.ravel()
    values, first = np.unique(flat, return_index=True)
    values, first = values[values > 0], first[values > 0]
    return np.array_equal(values, np.arange(1, n + 1)) and bool(np.all(np.diff(first) > 0))


def bfs_labels(free: np.ndarray, connectivity: int, wrap0: bool, wrap1: bool) -> np.ndarray:
    """Reference labelling by breadth-first search, seeds in raster order (plain Python)."""
    ny, nx = free.shape
    steps = [(-1, 0), (1, 0), (0, -1), (0, 1)]
    if connectivity == 8:
        steps += [(-1, -1), (-1, 1), (1, -1), (1, 1)]
    lab = np.zeros(free.shape, dtype=np.int64)
    f = free.tolist()
    out = lab.tolist()
    k = 0
    for i0 in range(ny):
        for j0 in range(nx):
            if not f[i0][j0] or out[i0][j0]:
                continue
            k += 1
            out[i0][j0] = k
            queue = deque([(i0, j0)])
            while queue:
                i, j = queue.popleft()
                for di, dj in steps:
                    a, b = i + di, j + dj
                    if wrap0:
                        a %= ny
                    if wrap1:
                        b %= nx
                    if 0 <= a < ny and 0 <= b < nx and f[a][b] and not out[a][b]:
                        out[a][b] = k
                        queue.append((a, b))
    return np.array(out, dtype=np.int64).reshape(free.shape)


def random_shape(rng: np.random.Generator, big: bool) -> tuple[int, int]:
    if big:
        return int(rng.integers(150, 301)), int(rng.integers(150, 301))
    # Log-uniform sizes from 1 to ~120: many tiny and thin masks, some medium.
    ny, nx = np.exp(rng.uniform(0, np.log(120), size=2)).astype(int)
    return int(ny), int(nx)


# ---------------------------------------------------------------------------------------------
# labels against scipy


@pytest.mark.parametrize("connectivity", [4, 8])
def test_labels_match_scipy_on_random_masks(connectivity: int) -> None:
    """5,000 masks per connectivity (10,000 in all), 1 and 2 threads."""
    rng = np.random.default_rng(20240 + connectivity)
    structure = FOUR if connectivity == 4 else EIGHT
    n_masks = 5000
    for m in range(n_masks):
        ny, nx = random_shape(rng, big=m % 250 == 0)
        p = rng.uniform(0.3, 0.8)
        free = rng.random((ny, nx)) < p
        ref, n_ref = ndimage.label(free, structure=structure)
        lab1, n1 = _core.label_clusters(free, connectivity, threads=1)
        lab2, n2 = _core.label_clusters(free, connectivity, threads=2)
        assert lab1.dtype == np.uint32 and lab1.shape == free.shape
        assert n1 == n2 == n_ref, (m, ny, nx, p)
        assert np.array_equal(lab1, lab2), (m, ny, nx, p)
        assert same_partition(lab1, ref), (m, ny, nx, p)
        assert raster_numbered(lab1, n1), (m, ny, nx, p)


@pytest.mark.parametrize("connectivity", [4, 8])
def test_labels_match_scipy_across_many_strips(connectivity: int) -> None:
    """Grids large enough to be split into many strips, including thin and wide ones."""
    rng = np.random.default_rng(7 + connectivity)
    structure = FOUR if connectivity == 4 else EIGHT
    for ny, nx in [(1200, 700), (3000, 40), (40, 3000), (5000, 3), (700, 1)]:
        for p in (0.45, 0.593, 0.7):
            free = rng.random((ny, nx)) < p
            ref, n_ref = ndimage.label(free, structure=structure)
            lab, n = _core.label_clusters(free, connectivity, threads=2)
            assert n == n_ref
            assert same_partition(lab, ref)
            assert raster_numbered(lab, n)


def test_labels_are_the_same_for_any_thread_count() -> None:
    rng = np.random.default_rng(3)
    free = rng.random((1500, 1100)) < 0.6
    gap = rng.random(free.shape)
    runs = [percolation(gap, dx=0.1, contact=~free, threads=t) for t in (1, 2, 3)]
    for other in runs[1:]:
        assert np.array_equal(runs[0].labels, other.labels)
        # Bit for bit: the sums' order does not depend on the threads.
        assert runs[0].volumes.tobytes() == other.volumes.tobytes()
        assert runs[0].spanning_volume == other.spanning_volume
    default = percolation(gap, dx=0.1, contact=~free)
    assert np.array_equal(default.labels, runs[0].labels)


def test_non_contiguous_inputs() -> None:
    rng = np.random.default_rng(11)
    base = rng.random((90, 130)) < 0.6
    ref, _ = _core.label_clusters(np.ascontiguousarray(base))
    lab_f, _ = _core.label_clusters(np.asfortranarray(base))
    assert np.array_equal(lab_f, ref)
    big = rng.random((180, 260)) < 0.6
    view = big[::2, ::2]
    lab_v, n_v = _core.label_clusters(view)
    ref_v, n_ref = ndimage.label(view, structure=FOUR)
    assert n_v == n_ref and same_partition(lab_v, ref_v)
    gap = rng.random((130, 90)).T  # Fortran order
    a = percolation(gap, dx=1.0, contact=~base)
    b = percolation(np.ascontiguousarray(gap), dx=1.0, contact=np.ascontiguousarray(~base))
    assert np.array_equal(a.labels, b.labels)
    assert a.volumes.tobytes() == b.volumes.tobytes()


def test_empty_and_degenerate_masks() -> None:
    lab, n = _core.label_clusters(np.zeros((0, 4), dtype=bool))
    assert lab.shape == (0, 4) and n == 0
    lab, n = _core.label_clusters(np.ones((1, 1), dtype=bool))
    assert n == 1 and lab[0, 0] == 1
    lab, n = _core.label_clusters(np.zeros((3, 5), dtype=bool))
    assert n == 0 and not lab.any()


# ---------------------------------------------------------------------------------------------
# periodic wrap against a breadth-first search


@pytest.mark.parametrize("connectivity", [4, 8])
def test_periodic_wrap_matches_bfs(connectivity: int) -> None:
    rng = np.random.default_rng(100 + connectivity)
    cases = 0
    for m in range(300):
        ny, nx = (int(v) for v in rng.integers(1, 40, size=2))
        p = rng.uniform(0.3, 0.8)
        free = rng.random((ny, nx)) < p
        wrap0, wrap1 = bool(m % 3 != 1), bool(m % 3 != 0)
        ref = bfs_labels(free, connectivity, wrap0, wrap1)
        lab, n = _core.label_clusters(free, connectivity, wrap0, wrap1, threads=1 + m % 2)
        # The BFS seeds clusters in raster order, so the numbering must agree exactly.
        assert np.array_equal(lab, ref), (m, ny, nx, wrap0, wrap1)
        assert n == int(ref.max(initial=0))
        cases += 1
    assert cases == 300


@pytest.mark.parametrize("connectivity", [4, 8])
def test_periodic_wrap_matches_bfs_across_strips(connectivity: int) -> None:
    rng = np.random.default_rng(200 + connectivity)
    for (ny, nx), wraps in [((330, 300), (True, True)), ((900, 40), (True, False))]:
        free = rng.random((ny, nx)) < 0.6
        ref = bfs_labels(free, connectivity, *wraps)
        lab, _ = _core.label_clusters(free, connectivity, *wraps, threads=2)
        assert np.array_equal(lab, ref)


# ---------------------------------------------------------------------------------------------
# hand-made geometries


def gap_from(rows: list[str], value: float = 1.0) -> np.ndarray:
    """'.' free (gap = value), '#' contact (gap = 0)."""
    return np.array([[value if c == "." else 0.0 for c in r] for r in rows])


def test_straight_channel_spans() -> None:
    g = gap_from(["##.##", "##.##", "##.##", "##.##"])
    p = percolation(g, dx=1.0)
    assert (p.n_clusters, p.n_spanning) == (1, 1) and p.percolates
    assert list(p.classes) == [SPANNING]
    assert p.spanning_volume == p.free_volume == 4.0
    # Across the channel it only touches the first and last rows: dead end for axis 1.
    q = percolation(g, dx=1.0, axis=1)
    assert list(q.classes) == [DEAD_END] and not q.percolates


def test_blocked_channel_does_not_span() -> None:
    g = gap_from(["##.##", "##.##", "#####", "##.##"])
    p = percolation(g, dx=1.0)
    assert p.n_clusters == 2 and not p.percolates
    assert list(p.classes) == [DEAD_END, DEAD_END]
    assert p.spanning_volume == 0.0 and p.dead_end_volume == p.free_volume == 3.0


def test_channel_touching_one_side_is_dead_end() -> None:
    g = gap_from(["#####", "...##", "#####"])
    p = percolation(g, dx=2.0)
    assert list(p.classes) == [DEAD_END]
    assert p.dead_end_volume == 3 * 1.0 * 2.0**2
    # A periodic surface wraps across axis 0's flow (columns): the left edge is no boundary.
    q = percolation(g, dx=2.0, periodic=True)
    assert list(q.classes) == [TRAPPED]


def test_enclosed_pocket_is_trapped() -> None:
    g = gap_from(["#####", "#..##", "#.###", "#####"], value=0.5)
    p = percolation(g, dx=1.0, axis="either")
    assert list(p.classes) == [TRAPPED]
    assert p.trapped_volume == p.free_volume == 1.5
    assert p.trapped_cells == p.free_cells == 3
    assert p.trapped_area == p.free_area == 3.0  # dx = 1: cells × dx²
    assert p.class_map().tolist() == [
        [0, 0, 0, 0, 0],
        [0, 3, 3, 0, 0],
        [0, 3, 0, 0, 0],
        [0, 0, 0, 0, 0],
    ]


def spiral(n: int, margin: int, exit_to_edge: bool) -> tuple[np.ndarray, int]:
    """A square spiral corridor walked out from the centre of an ``n × n`` grid.

    Arms are two cells apart, so one wall cell separates them: the corridor is one cluster,
    with 4- and with 8-connectivity. It stays ``margin`` cells away from the edges; with
    ``exit_to_edge`` its outer end continues straight to the edge, which it then touches at
    exactly one cell. Returns the free mask and the number of corridor cells.
    """
    free = np.zeros((n, n), dtype=bool)
    r = c = n // 2
    free[r, c] = True
    lo, hi = margin, n - margin
    dirs = [(0, 1), (1, 0), (0, -1), (-1, 0)]
    step, d = 1, 0
    while True:
        for _ in range(2):
            dr, dc = dirs[d % 4]
            for _ in range(2 * step):
                if not (lo <= r + dr < hi and lo <= c + dc < hi):
                    if exit_to_edge:
                        while 0 <= r + dr < n and 0 <= c + dc < n:
                            r, c = r + dr, c + dc
                            free[r, c] = True
                    return free, int(free.sum())
                r, c = r + dr, c + dc
                free[r, c] = True
            d += 1
        step += 1


@pytest.mark.parametrize("connectivity", [4, 8])
def test_spiral_is_one_cluster(connectivity: int) -> None:
    # Large enough to run through many strips and back many times.
    free, cells = spiral(801, margin=3, exit_to_edge=True)
    gap = np.where(free, 0.25, 0.0)
    for axis in (0, 1, "either", "both"):
        p = percolation(gap, dx=1.0, axis=axis, connectivity=connectivity)
        assert p.n_clusters == 1
        assert int(p.cell_counts[0]) == cells
        # It touches one edge at one cell: it cannot span, whatever the flow direction.
        assert list(p.classes) == [DEAD_END] and not p.percolates
        assert p.dead_end_volume == pytest.approx(0.25 * cells, rel=1e-12)
    closed, cells = spiral(801, margin=3, exit_to_edge=False)
    p = percolation(np.where(closed, 1.0, 0.0), dx=1.0, connectivity=connectivity)
    assert p.n_clusters == 1 and int(p.cell_counts[0]) == cells
    assert list(p.classes) == [TRAPPED]


def test_serpentine_spans() -> None:
    """A corridor winding left and right from the first row to the last is one spanning
    cluster, though it crosses the grid only once per turn."""
    ny, nx = 601, 50
    free = np.zeros((ny, nx), dtype=bool)
    free[0::2, 1:-1] = True
    for i in range(1, ny, 2):
        free[i, 1 if (i // 2) % 2 else nx - 2] = True
    p = percolation(np.where(free, 1.0, 0.0), dx=1.0)
    assert p.n_clusters == 1 and list(p.classes) == [SPANNING]
    q = percolation(np.where(free, 1.0, 0.0), dx=1.0, axis=1)
    assert list(q.classes) == [DEAD_END]


def test_diagonal_connection_only_with_eight() -> None:
    g = gap_from([".#", "#."])
    four = percolation(g, dx=1.0, connectivity=4)
    eight = percolation(g, dx=1.0, connectivity=8)
    assert four.n_clusters == 2 and four.n_spanning == 0
    assert eight.n_clusters == 1 and eight.n_spanning == 1
    assert four.labels.tolist() == [[1, 0], [0, 2]]
    assert eight.labels.tolist() == [[1, 0], [0, 1]]
    # The diagonal across the periodic wrap: (0, last) touches (1, 0) only with 8.
    lab4, n4 = _core.label_clusters(np.array([[0, 0, 1], [1, 0, 0]], bool), 4, False, True)
    lab8, n8 = _core.label_clusters(np.array([[0, 0, 1], [1, 0, 0]], bool), 8, False, True)
    assert (n4, n8) == (2, 1)


def test_either_and_both() -> None:
    cross = gap_from(["##.##", "#...#", ".....", "#...#", "##.##"])
    line = gap_from(["#####", ".....", "#####"])
    assert percolation(cross, dx=1.0, axis="both").percolates
    assert percolation(line, dx=1.0, axis="either").percolates
    both = percolation(line, dx=1.0, axis="both")
    assert not both.percolates and list(both.classes) == [DEAD_END]
    assert both.axis == "both" and both.periodic is False


# ---------------------------------------------------------------------------------------------
# volumes


@pytest.mark.parametrize("axis", [0, 1, "either", "both"])
@pytest.mark.parametrize("connectivity", [4, 8])
def test_class_volumes_add_up_to_the_free_volume(axis, connectivity) -> None:
    rng = np.random.default_rng(17)
    for ny, nx, p in [(257, 129, 0.55), (64, 300, 0.62), (1000, 800, 0.6), (5, 7, 0.5)]:
        free = rng.random((ny, nx)) < p
        gap = np.where(free, rng.lognormal(0.0, 2.0, size=free.shape), 0.0)
        dx = 0.37
        res = percolation(gap, dx=dx, axis=axis, connectivity=connectivity, contact=~free)
        parts = res.spanning_volume + res.dead_end_volume + res.trapped_volume
        assert abs(parts - res.free_volume) <= 1e-12 * res.free_volume
        assert res.free_volume == pytest.approx(gap[free].sum() * dx * dx, rel=1e-12)
        assert res.free_cells == int(free.sum())
        assert res.free_area == pytest.approx(int(free.sum()) * dx * dx, rel=1e-15, abs=0)
        assert res.n_spanning + res.n_dead_end + res.n_trapped == res.n_clusters
        # Per cluster, against numpy.
        ref_v = np.bincount(res.labels.ravel(), weights=gap.ravel(), minlength=res.n_clusters + 1)
        ref_a = np.bincount(res.labels.ravel(), minlength=res.n_clusters + 1)
        np.testing.assert_allclose(res.volumes, ref_v[1:] * dx * dx, rtol=1e-12)
        assert np.array_equal(res.cell_counts, ref_a[1:])
        np.testing.assert_allclose(res.areas, ref_a[1:] * dx * dx, rtol=1e-15)
        for code, vol in [
            (SPANNING, res.spanning_volume),
            (DEAD_END, res.dead_end_volume),
            (TRAPPED, res.trapped_volume),
        ]:
            assert vol == pytest.approx(res.volumes[res.classes == code].sum(), rel=1e-12, abs=0)


def test_classes_against_numpy_reference() -> None:
    """Classes from scipy labels and the labels seen on each edge (the benchmark's method)."""
    rng = np.random.default_rng(5)
    free = rng.random((300, 200)) < 0.6
    ref, n = ndimage.label(free, structure=FOUR)
    top, bottom = np.unique(ref[0]), np.unique(ref[-1])
    left, right = np.unique(ref[:, 0]), np.unique(ref[:, -1])
    span = np.intersect1d(top, bottom)
    edge = np.union1d(np.union1d(top, bottom), np.union1d(left, right))
    res = percolation(np.where(free, 1.0, 0.0), dx=1.0)
    # Map our clusters to scipy's through any cell.
    ours_to_ref = np.zeros(n + 1, dtype=np.int64)
    ours_to_ref[res.labels.ravel()] = ref.ravel()
    expected = np.where(
        np.isin(ours_to_ref[1:], span[span > 0]),
        SPANNING,
        np.where(np.isin(ours_to_ref[1:], edge[edge > 0]), DEAD_END, TRAPPED),
    )
    assert np.array_equal(res.classes, expected)


def test_gap_array_without_mask_uses_positive_gap() -> None:
    g = np.array([[1.0, -0.5, 0.0, 2.0], [0.5, 0.0, 0.0, 3.0]])
    p = percolation(g, dx=1.0)
    assert p.labels.tolist() == [[1, 0, 0, 2], [1, 0, 0, 2]]
    assert p.free_volume == 6.5
    assert list(p.classes) == [SPANNING, SPANNING]


def test_contact_state_and_boundary() -> None:
    # A channel leaving at the right edge and coming back at the left one.
    g = gap_from(["###.#", ".##..", ".####", ".####"])
    state = SimpleNamespace(gap=g, contact=g <= 0, dx=0.5, boundary="periodic")
    p = percolation(state)
    assert isinstance(p, Percolation)
    assert p.periodic and p.n_clusters == 1 and p.percolates
    assert p.dx == 0.5 and p.free_volume == pytest.approx(6 * 0.25)
    # The free patch: no wrap, two dead ends.
    q = percolation(SimpleNamespace(gap=g, contact=g <= 0, dx=0.5, boundary="free"))
    assert not q.periodic and q.n_clusters == 2 and not q.percolates
    # "either"/"both" never wrap: the periodic cell is analysed as one patch.
    e = percolation(state, axis="either")
    assert not e.periodic and e.n_clusters == 2
    assert percolation(state, periodic=False).n_clusters == 2
    assert CLASS_NAMES[int(p.classes[0])] == "spanning"


def test_real_contact_state() -> None:
    contact_mod = pytest.importorskip("leakpath.contact")
    generators = pytest.importorskip("leakpath.generators")
    surf = generators.rmd(5, 2.1, seed=1)
    state = contact_mod.solve(surf, 0.5 * surf.height_range)
    p = percolation(state)
    assert p.free_cells == int((~state.contact).sum())
    assert p.free_volume == pytest.approx(state.gap[~state.contact].sum() * state.dx**2)


# ---------------------------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"gap": np.array([[0.0, np.nan]])}, "gap"),
        ({"gap": np.array([[0.0, np.inf]])}, "gap"),
        ({"gap": np.ones(5)}, "gap"),
        ({"gap": np.ones((2, 2, 2))}, "gap"),
        ({"gap": np.ones((0, 3))}, "gap"),
        ({"gap": [["a", "b"]]}, "gap"),
        ({"axis": 2}, "axis"),
        ({"axis": "diagonal"}, "axis"),
        ({"axis": True}, "axis"),
        ({"axis": None}, "axis"),
        ({"connectivity": 6}, "connectivity"),
        ({"connectivity": 4.0}, "connectivity"),
        ({"dx": None}, "dx"),
        ({"dx": 0.0}, "dx"),
        ({"dx": -1.0}, "dx"),
        ({"dx": float("nan")}, "dx"),
        ({"contact": np.zeros((3, 3), bool)}, "contact"),
        ({"contact": np.zeros((2, 2))}, "contact"),
        ({"periodic": "yes"}, "periodic"),
        ({"periodic": True, "axis": "either"}, "periodic"),
        ({"threads": 0}, "threads"),
    ],
)
def test_bad_input_names_the_argument(kwargs: dict, name: str) -> None:
    args = {"gap": np.ones((2, 2)), "dx": 1.0}
    args.update(kwargs)
    gap = args.pop("gap")
    with pytest.raises(ValueError, match=rf"^{name}\b"):
        percolation(gap, **args)


def test_bad_state_arguments() -> None:
    state = SimpleNamespace(gap=np.ones((2, 2)), contact=np.zeros((2, 2), bool), dx=1.0)
    with pytest.raises(ValueError, match=r"^dx\b"):
        percolation(state, dx=2.0)
    with pytest.raises(ValueError, match=r"^contact\b"):
        percolation(state, contact=np.zeros((2, 2), bool))
    bad = SimpleNamespace(gap=np.array([[np.nan]]), contact=np.zeros((1, 1), bool), dx=1.0)
    with pytest.raises(ValueError, match=r"^gap\b"):
        percolation(bad)


def test_core_rejects_bad_arguments() -> None:
    free = np.ones((3, 3), dtype=bool)
    gap = np.ones((3, 3))
    with pytest.raises(ValueError, match=r"^connectivity\b"):
        _core.label_clusters(free, 6)
    with pytest.raises(ValueError, match=r"^threads\b"):
        _core.label_clusters(free, threads=0)
    lab = _core.label_open(gap, 1.0)
    assert [c.axis for c in _core.classify(lab, [1, "both", 0, "either"])] == [
        1, "both", 0, "either"
    ]
    for bad in (2, "2", "0", True, 0.0, None):
        with pytest.raises(ValueError, match=r"^axis\b"):
            _core.classify(lab, [0, bad])
    with pytest.raises(ValueError, match=r"^periodic_axis0\b"):
        _core.classify(_core.label_open(gap, 1.0, periodic_axis0=True), [0])
    with pytest.raises(ValueError, match=r"^periodic_axis1\b"):
        _core.classify(_core.label_open(gap, 1.0, periodic_axis1=True), ["either"])
    with pytest.raises(ValueError, match=r"^contact\b"):
        _core.label_open(gap, 1.0, contact=np.ones((2, 3), dtype=bool))
    with pytest.raises(ValueError, match=r"^dx\b"):
        _core.label_open(gap, 0.0)
    with pytest.raises(ValueError, match=r"^gap\b"):
        _core.label_open(np.full((3, 3), np.nan), 1.0)
    # The flow takes a labelling made with its own connectivity and wrap only.
    with pytest.raises(ValueError, match=r"^labels\b"):
        _core.solve_reynolds_flow(gap, 1.0, labels=_core.label_open(gap, 1.0, connectivity=8))
    with pytest.raises(ValueError, match=r"^labels\b"):
        _core.solve_reynolds_flow(gap, 1.0, labels=_core.label_open(np.ones((3, 4)), 1.0))
    with pytest.raises(ValueError, match=r"^labels\b"):  # labels of other open cells
        _core.solve_reynolds_flow(
            np.where(np.eye(3, dtype=bool), 0.0, 1.0), 1.0, labels=_core.label_open(gap, 1.0)
        )
    with pytest.raises(ValueError, match=r"^axis\b"):
        _core.solve_reynolds_flow(gap, 1.0, axis="either")
    # Too many cells for u32 indices: refused before anything is allocated (the inputs are
    # zero-stride views, so they cost no memory either).
    with pytest.raises(ValueError, match=r"^free\b"):
        _core.label_clusters(np.broadcast_to(np.True_, (70_000, 70_000)))
    with pytest.raises(ValueError, match=r"^gap\b"):
        percolation(np.broadcast_to(1.0, (70_000, 70_000)), dx=1.0)
