"""Reynolds flow through a contact gap: leakpath against pyamg and scipy on the same matrix.

Run from the repository root (after ``pip install .`` and ``pip install pyamg scipy``)::

    python benchmarks/flow_bench.py                    # writes benchmarks/results/flow.md
    python benchmarks/flow_bench.py --sizes 1025 --repeats 5

Inputs:

* **1025²**: the gap of a solved contact, ``leakpath.solve(surface, Δ,
  solver="polonsky-keer")`` on a spectral surface (H = 0.8, rms height 1, seed 0, free
  periodic boundary), Δ chosen (by bisection on a 257² surface of the same statistics) for
  about 40 % contact; the flow wraps across axis 0 like the surface.
* **4097²**: a synthetic gap ``max(t − h, 0)`` on a spectral surface (H = 0.8, seed 0), ``t``
  the lowest quantile level from 60 % up that leaves a cluster spanning along axis 0; a
  contact solve at this size takes minutes, the flow problem has the same structure.

leakpath: ``leakpath.flow`` with its default solver (the sparse Cholesky factor wherever it
fits in memory, ``Flow.solver`` names it) and
with ``solver="multigrid"`` (aggregation-multigrid preconditioned CG), each including
labelling, assembly and fluxes. pyamg: ``smoothed_aggregation_solver(A)`` then
``solve(b, tol, accel="cg")`` on the same finite-volume matrix (assembled here with
scipy.sparse on the spanning cells); its setup and solve are timed separately and
together. scipy: ``spsolve`` on that matrix. The iterative solvers use the same relative
residual ``‖b − Ax‖₂/‖b‖₂ ≤ 1e-12``; the flow rates are compared. Timings are medians of
``--repeats`` runs. Peak memory of ``leakpath.flow`` at the largest size is the
peak resident set (VmHWM) of a child process that loads the gap and solves, beside that of
a child that only loads it.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy import ndimage

import leakpath

TOL = 1e-12


def machine() -> str:
    cpu = platform.processor() or "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}"


def contact_gap(n: int) -> tuple[np.ndarray, np.ndarray, bool, str]:
    """Gap and contact of a Polonsky–Keer solve with about 40 % contact."""
    def full(surf):  # periodic: full contact at max h − mean h
        return float(surf.heights.max() - surf.heights.mean())

    small = leakpath.spectral(257, 0.8, seed=0, rms_height=1.0)
    lo, hi = 0.0, full(small)
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        a = leakpath.solve(
            small, mid, boundary="periodic", solver="polonsky-keer", tol=1e-8
        ).contact_fraction
        lo, hi = (mid, hi) if a < 0.4 else (lo, mid)
    s = leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)
    delta = 0.5 * (lo + hi) / full(small) * full(s)
    t0 = time.perf_counter()
    st = leakpath.solve(s, delta, boundary="periodic", solver="polonsky-keer")
    t = time.perf_counter() - t0
    what = (
        f"contact gap, periodic Polonsky–Keer at Δ = {delta:.4f} "
        f"({delta / full(s):.3f} of full contact), "
        f"contact fraction {st.contact_fraction:.3f} (contact solve {t:.1f} s)"
    )
    return np.maximum(st.gap, 0.0), st.contact, True, what


def synthetic_gap(n: int) -> tuple[np.ndarray, np.ndarray, bool, str]:
    s = leakpath.spectral(n, 0.8, seed=0, rms_height=1.0)
    h = s.heights
    for q in np.arange(0.60, 0.96, 0.02):
        t = np.quantile(h, q)
        gap = np.maximum(t - h, 0.0)
        if leakpath.percolation(gap, dx=s.dx).percolates:
            contact = gap <= 0
            what = (
                f"synthetic gap max(t − h, 0), t at the {q:.2f} quantile, contact fraction "
                f"{contact.mean():.3f}"
            )
            return gap, contact, False, what
    raise SystemExit("no spanning cluster found")


def assemble(gap: np.ndarray, contact: np.ndarray, periodic: bool):
    """The finite-volume matrix of docs/flow.md on the spanning cells (η = 1, Δp = 1).

    With ``periodic`` the grid wraps across axis 1: done by appending column 0 after the last
    column for the faces, and by joining labels across the wrap.
    """
    ny, nx = gap.shape
    c = np.where(contact, 0.0, gap**3 / 12.0)
    open_ = c > 0
    lab, k = ndimage.label(open_)
    if periodic:
        parent = np.arange(k + 1)

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        for a, b in zip(lab[:, 0], lab[:, -1], strict=True):
            if a and b:
                ra, rb = find(a), find(b)
                parent[max(ra, rb)] = min(ra, rb)
        roots = np.array([find(a) for a in range(k + 1)])
        lab = roots[lab]
    span = np.intersect1d(lab[0][lab[0] > 0], lab[-1][lab[-1] > 0])
    cells = np.isin(lab, span)
    idx = -np.ones(gap.shape, dtype=np.int64)
    m = int(cells.sum())
    idx[cells] = np.arange(m)
    diag = np.zeros(gap.shape)
    rows, cols, vals = [], [], []
    # Periodic: the faces across axis 1 include the wrap (last column, first column).
    idx_w = np.concatenate([idx, idx[:, :1]], axis=1) if periodic else idx
    c_w = np.concatenate([c, c[:, :1]], axis=1) if periodic else c
    for a, b, ca, cb in (
        (idx[:-1, :], idx[1:, :], c[:-1, :], c[1:, :]),
        (idx_w[:, :-1], idx_w[:, 1:], c_w[:, :-1], c_w[:, 1:]),
    ):
        ok = (a >= 0) & (b >= 0)
        cf = 2 * ca[ok] * cb[ok] / (ca[ok] + cb[ok])
        rows += [a[ok], b[ok]]
        cols += [b[ok], a[ok]]
        vals += [-cf, -cf]
    # Diagonal: sum of faces + reservoir faces.
    face_v = np.zeros((ny - 1, nx))
    okv = (idx[:-1] >= 0) & (idx[1:] >= 0)
    face_v[okv] = 2 * c[:-1][okv] * c[1:][okv] / (c[:-1][okv] + c[1:][okv])
    m_h = idx_w.shape[1] - 1
    face_h = np.zeros((ny, m_h))
    okh = (idx_w[:, :-1] >= 0) & (idx_w[:, 1:] >= 0)
    ca, cb = c_w[:, :-1][okh], c_w[:, 1:][okh]
    face_h[okh] = 2 * ca * cb / (ca + cb)
    diag[:-1] += face_v
    diag[1:] += face_v
    diag[:, :m_h] += face_h[:, :m_h]
    if periodic:
        diag[:, 1:] += face_h[:, : nx - 1]
        diag[:, 0] += face_h[:, nx - 1]
    else:
        diag[:, 1:] += face_h
    diag[0] += 2 * c[0]
    diag[-1] += 2 * c[-1]
    rows.append(idx[cells])
    cols.append(idx[cells])
    vals.append(diag[cells])
    A = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, m)
    )
    b = np.zeros(gap.shape)
    b[0] = 2 * c[0]
    bvec = b[cells]
    out_w = np.zeros(gap.shape)
    out_w[-1] = 2 * c[-1]
    return A, bvec, out_w[cells]


def median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def peak_memory(gap_path: str, periodic: bool) -> tuple[float, float]:
    """Peak RSS (MiB) of a child that loads the gap, and of one that also solves the flow."""
    # VmHWM of the child's own address space (ru_maxrss would carry the parent's peak over
    # fork + exec on Linux).
    report = (
        "print([int(x.split()[1]) for x in open('/proc/self/status') "
        "if x.startswith('VmHWM')][0])"
    )
    load = f"import numpy as np, leakpath; g = np.load({gap_path!r})"
    solve = f"; f = leakpath.flow(g, dx=1.0, tol={TOL}, periodic={periodic})"
    out = []
    for code in (load, load + solve):
        run = subprocess.run(
            [sys.executable, "-c", f"{code}; {report}"], check=True, capture_output=True,
            text=True,
        )
        out.append(int(run.stdout.split()[-1]) / 1024)
    return out[0], out[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1025, 4097])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--pyamg-max", type=int, default=1025, help="largest size given to pyamg")
    ap.add_argument("--pyamg-repeats", type=int, default=None, help="default: --repeats")
    ap.add_argument("--multigrid-max", type=int, default=4097, help="largest size for multigrid")
    ap.add_argument("--spsolve-max", type=int, default=1025, help="largest size for spsolve")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/flow.md"))
    args = ap.parse_args()
    import pyamg

    load0 = os.getloadavg()
    lines = [
        "# Reynolds flow benchmark",
        "",
        f"Command: `python benchmarks/flow_bench.py {' '.join(sys.argv[1:])}`".rstrip(),
        "",
        f"- machine: {machine()}",
        f"- leakpath {leakpath.__version__}, numpy {np.__version__}, scipy "
        f"{importlib.metadata.version('scipy')}, pyamg {pyamg.__version__}, Python "
        f"{platform.python_version()}",
        f"- relative residual tolerance {TOL:g} for leakpath and pyamg; medians of "
        f"{args.repeats} runs (pyamg: {args.pyamg_repeats or args.repeats})",
        f"- load average before: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}",
        "",
        "| grid | gap | unknowns | solver | median s | iterations | Q | rel. diff. Q |",
        "|---|---|---|---|---|---|---|---|",
    ]
    largest = max(args.sizes)
    mem_line = ""
    for n in args.sizes:
        gap, contact, periodic, what = contact_gap(n) if n <= 1025 else synthetic_gap(n)
        print(f"{n}²: {what}", flush=True)
        tl, f = median_time(
            lambda g=gap, c=contact, w=periodic: leakpath.flow(
                g, dx=1.0, contact=c, tol=TOL, periodic=w
            ),
            args.repeats,
        )
        q = f.flow_rate
        default = f.solver
        rows = [(f"leakpath.flow (default: {default})", tl, f.iterations, q)]
        print(f"  leakpath {tl:.3f} s, {f.iterations} it, Q = {q:.12e}", flush=True)
        if n <= args.multigrid_max:
            t0 = time.perf_counter()
            try:
                tm, fm = median_time(
                    lambda g=gap, c=contact, w=periodic: leakpath.flow(
                        g, dx=1.0, contact=c, tol=TOL, periodic=w, solver="multigrid"
                    ),
                    args.pyamg_repeats or args.repeats,
                )
                rows.append(("leakpath.flow (multigrid forced)", tm, fm.iterations, fm.flow_rate))
                print(f"  leakpath multigrid {tm:.3f} s, {fm.iterations} it", flush=True)
            except leakpath.errors.NotConvergedError as e:
                tm = time.perf_counter() - t0
                rows.append((f"leakpath.flow (multigrid forced): raised {e}", tm, None, None))
                print(f"  leakpath multigrid raised after {tm:.3f} s: {e}", flush=True)
        if n <= args.pyamg_max or n <= args.spsolve_max:
            A, b, w = assemble(gap, contact, periodic)
        if n <= args.pyamg_max:
            reps = args.pyamg_repeats or args.repeats
            ts, ml = median_time(lambda A=A: pyamg.smoothed_aggregation_solver(A), reps)
            res: list[float] = []

            def amg_solve(ml=ml, b=b, res=res):
                res.clear()
                return ml.solve(b, tol=TOL, accel="cg", maxiter=20000, residuals=res)

            tsol, x = median_time(amg_solve, reps)
            qa = float(w @ x)
            rows.append(("pyamg SA setup", ts, None, None))
            rows.append(("pyamg SA + CG solve", tsol, len(res) - 1, qa))
            rows.append(("pyamg SA setup + solve", ts + tsol, len(res) - 1, qa))
            print(f"  pyamg setup {ts:.3f} s, solve {tsol:.3f} s, Q = {qa:.12e}", flush=True)
        if n <= args.spsolve_max:
            tsp, x = median_time(lambda A=A, b=b: spla.spsolve(A.tocsc(), b), args.repeats)
            qs = float(w @ x)
            rows.append(("scipy spsolve", tsp, None, qs))
            print(f"  spsolve {tsp:.3f} s, Q = {qs:.12e}", flush=True)
        for name, t, it, qq in rows:
            diff = "" if qq is None else f"{abs(qq / q - 1):.1e}"
            qs_ = "" if qq is None else f"{qq:.10e}"
            lines.append(
                f"| {n}² | {what} | {f.n_unknowns} | {name} | {t:.3f} | "
                f"{'' if it is None else it} | {qs_} | {diff} |"
            )
        for other in ("scipy spsolve",):
            t_other = [t for name, t, _, _ in rows if name == other]
            if t_other:
                lines.append(
                    f"| | | | **leakpath (default) speed-up over {other}** | "
                    f"{t_other[0] / tl:.2f}× | | | |"
                )
        speed = [t for name, t, _, _ in rows if name == "pyamg SA setup + solve"]
        if speed:
            lines.append(f"| | | | **leakpath speed-up over pyamg (setup + solve)** | "
                         f"{speed[0] / tl:.2f}× | | | |")
        lines.append(f"| | | | inlet/outlet rel. diff., conservation, residual | "
                     f"{abs(f.inlet_flow_rate / q - 1):.1e}, {f.conservation:.1e}, "
                     f"{f.residual:.1e} | | | |")
        if n == largest:
            with tempfile.TemporaryDirectory() as d:
                path = os.path.join(d, "gap.npy")
                np.save(path, np.where(contact, 0.0, gap))
                base, peak = peak_memory(path, periodic)
            mem_line = (
                f"Peak memory at {n}² (VmHWM of a child process): load only {base:.0f} MiB, "
                f"load + leakpath.flow {peak:.0f} MiB, so the solve adds {peak - base:.0f} MiB "
                f"({(peak - base) * 2**20 / gap.size:.0f} bytes per cell)."
            )
            print(mem_line, flush=True)
    load1 = os.getloadavg()
    lines += [
        "",
        mem_line,
        "",
        f"Load average after: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}",
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # Earlier runs stay below the new one, as the record of what changed.
    earlier = args.out.read_text() if args.out.exists() else ""
    if earlier:
        earlier = "\n## Earlier runs\n\n" + earlier.replace("# Reynolds flow benchmark", "###", 1)
    args.out.write_text("\n".join(lines) + earlier)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
