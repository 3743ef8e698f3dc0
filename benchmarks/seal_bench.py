"""Wall time of the README's worked seal example, and the same run on a Dask LocalCluster.

    PYTHONPATH=python python benchmarks/seal_bench.py [--out DIR] [--no-check]

1. ``leakpath seal examples/seal_water.toml --out DIR/processes`` as a subprocess (local
   processes, one per core, one rayon thread each): 16 realisations × 6 pressures × 2 axes
   on 512² patches, plus the convergence check (2 realisations on 1024²). Its printed table
   is kept for the README. ``--no-check`` times the 16 × 6 × 2 workload alone.
2. The same configuration through ``leakpath.seal_leakage(..., scheduler=client)`` on a
   ``distributed.LocalCluster`` (2 worker processes × 1 thread): summary.csv,
   realisations.csv and check.csv must be byte-identical to step 1's.

Writes ``benchmarks/results/seal.md`` (machine, versions, wall times, tables).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "python"))

import leakpath  # noqa: E402
from leakpath._io import machine_info  # noqa: E402
from leakpath.seal import SealConfig  # noqa: E402

CONFIG = ROOT / "examples" / "seal_water.toml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/tmp/leakpath-seal-bench"))
    ap.add_argument("--no-check", action="store_true", help="skip the convergence check")
    ap.add_argument("--results", type=Path, default=ROOT / "benchmarks/results/seal.md")
    args = ap.parse_args()
    config: Path = CONFIG
    if args.no_check:
        cfg = SealConfig.from_toml(CONFIG)
        cfg = dataclasses.replace(cfg, check=dataclasses.replace(cfg.check, realisations=0))
        config = args.out / "seal_water_no_check.toml"
        args.out.mkdir(parents=True, exist_ok=True)
        config.write_text(_toml(cfg.to_dict()), encoding="utf-8")
    env = {**os.environ, "PYTHONPATH": str(ROOT / "python")}
    load_before = os.getloadavg()
    local = args.out / "processes"
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "leakpath", "seal", str(config), "--out", str(local),
         "--overwrite"],
        env=env, capture_output=True, text=True, check=True,
    )
    wall_local = time.perf_counter() - t0
    print(proc.stdout)

    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                     dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        t0 = time.perf_counter()
        result = leakpath.seal_leakage(config, out=args.out / "dask", overwrite=True,
                                       scheduler=client, progress=False)
        wall_dask = time.perf_counter() - t0
    names = ["summary.csv", "realisations.csv"] + (["check.csv"] if result.check else [])
    same = {n: (local / n).read_bytes() == (args.out / "dask" / n).read_bytes() for n in names}
    print(f"local processes: {wall_local:.1f} s; Dask LocalCluster: {wall_dask:.1f} s; "
          f"identical: {same}")

    load_after = os.getloadavg()
    info = machine_info()
    cfg = result.config
    label = "without" if args.no_check else "with"
    lines = [
        f"## Worked example ({label} the convergence check)",
        "",
        f"`leakpath seal {config.relative_to(ROOT) if config.is_relative_to(ROOT) else config}"
        f" --out DIR` — {cfg.realisations} realisations × {len(cfg.mean_pressure)} pressures "
        f"× {len(cfg.axes)} axes on {result.metadata['patch']['n']}² patches"
        + ("" if args.no_check else f", check: {cfg.check.realisations} realisations on "
           f"{result.metadata['patch']['n'] * cfg.check.refine}²") + ".",
        "",
        f"- machine: {info['cpu']}, {info['cpu_count']} cores, "
        f"{(info['memory_bytes'] or 0) / 2**30:.1f} GiB; {info['platform']}",
        f"- versions: leakpath {info['leakpath']}, Python {info['python']}, numpy "
        f"{info['numpy']}, dask.distributed {_dask_version()}",
        f"- load average (1, 5, 15 min) before: {_load(load_before)}, after: "
        f"{_load(load_after)} (other work on the machine slows both runs)",
        f"- wall time, local processes (CLI, 2 workers × 1 thread): **{wall_local:.1f} s**",
        f"- wall time, Dask LocalCluster (2 workers × 1 thread): **{wall_dask:.1f} s**",
        f"- tables identical between the two: {', '.join(f'{n}: {v}' for n, v in same.items())}",
        "",
        "Printed table (local processes):",
        "",
        "```",
        proc.stdout.rstrip(),
        "```",
        "",
    ]
    text = "\n".join(lines)
    old = args.results.read_text(encoding="utf-8") if args.results.exists() else (
        "# Seal workflow benchmark\n\n`PYTHONPATH=python python benchmarks/seal_bench.py "
        "[--no-check]`\n\n")
    head = f"## Worked example ({label} the convergence check)"
    if head in old:
        before, _, after = old.partition(head)
        rest = after.split("\n## ", 1)
        old = before + (("## " + rest[1]) if len(rest) > 1 else "")
    args.results.write_text(old.rstrip() + "\n\n" + text, encoding="utf-8")
    return 0 if all(same.values()) else 1


def _load(avg: tuple[float, float, float]) -> str:
    return ", ".join(f"{x:.2f}" for x in avg)


def _dask_version() -> str:
    import distributed

    return distributed.__version__


def _toml(d: dict, prefix: str = "") -> str:
    import json

    scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
    out = [f"[{prefix}]"] if prefix and scalars else []
    out += [f"{k} = {json.dumps(v)}" for k, v in scalars.items()]
    out += [_toml(v, f"{prefix}.{k}" if prefix else k) for k, v in d.items()
            if isinstance(v, dict)]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    sys.exit(main())
