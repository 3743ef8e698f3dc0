"""Running tasks: one sweep per (parameter set, seed), serially, on local processes or on
a Dask cluster; worker set-up, a driver that writes each finished task at once."""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.connection import wait as _wait_ready
from pathlib import Path
from typing import Any

from .._outputs import OutputRecord
from .._sweep import sweep as _sweep
from ._aggregate import threshold_from_rows
from ._layout import _FORMAT, _TaskOutput, _TaskSpec, _write_task
from ._params import _generate, _generator_name

PathLike = str | os.PathLike[str]


_THREAD_ENV = ("RAYON_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")




def _run_task(spec: _TaskSpec) -> _TaskOutput:
    """Generate the surface, run the sweep, return its CSV and metadata (runs in a worker)."""
    t0 = time.perf_counter()
    c0 = time.process_time()
    surface = _generate(spec.generator, spec.params, spec.seed)
    result = _sweep(
        surface,
        levels=spec.levels,
        solver=spec.solver,
        warm_start=spec.warm_start,
        axis=spec.axis,
        connectivity=spec.connectivity,
        E=spec.E,
        nu=spec.nu,
        boundary=spec.boundary,
    )
    if spec.kill_once:  # test hook: a worker lost after doing its work
        try:
            os.remove(spec.kill_once)
        except FileNotFoundError:
            pass
        else:
            os._exit(1)
    seconds = time.perf_counter() - t0
    cpu_seconds = time.process_time() - c0
    meta = {
        "format": _FORMAT,
        "key": spec.key,
        "params": spec.params,
        "seed": spec.seed,
        "generator": _generator_name(spec.generator),
        "threshold": threshold_from_rows(result.rows, spec.axis),
        "task_seconds": seconds,
        # CPU time of the whole worker process (all its threads) during the task: the task's
        # own CPU time when the worker runs one task at a time (local processes).
        "task_cpu_seconds": cpu_seconds,
        "worker": {
            "host": socket.gethostname(),
            "pid": os.getpid(),
            "rayon_num_threads": os.environ.get("RAYON_NUM_THREADS"),
        },
        "sweep": result.metadata(),
    }
    return _TaskOutput(spec.key, spec.seed, result.csv_text(), meta, seconds)


def _run_task_dask(spec: _TaskSpec, threads: int | None) -> _TaskOutput:
    """:func:`_run_task` in a Dask worker, with ``RAYON_NUM_THREADS`` set first.

    ``threads=None``: 1 unless the worker's environment sets ``RAYON_NUM_THREADS``; an
    integer overrides it. Takes effect if rayon's global pool has not started in this worker
    process yet (it starts on the first Rust routine, i.e. in the first task).
    """
    if threads is None:
        os.environ.setdefault("RAYON_NUM_THREADS", "1")
    else:
        os.environ["RAYON_NUM_THREADS"] = str(int(threads))
    return _run_task(spec)


def _watch_driver(alive: Any) -> None:
    """Exit this worker as soon as the driver process is gone (never returns otherwise).

    ``alive`` is the read end of a pipe whose only write end the driver holds and never
    writes to: the read end sees end-of-file when the driver dies, however it dies, and
    unlike a probe of its process id it cannot mistake a killed driver that its own parent
    has not reaped yet (a zombie) for a live one.
    """
    try:
        alive.poll(None)
    except (OSError, EOFError):
        pass
    os._exit(1)


def _init_worker(threads: int, alive: Any = None) -> None:
    """Process-pool initializer: limit rayon (and BLAS) threads before any task runs.

    rayon builds its global pool on first use and reads ``RAYON_NUM_THREADS`` then, so
    setting it here — after ``leakpath`` may already have been imported, but before any
    Rust routine ran — takes effect. BLAS libraries read their variables when numpy is
    loaded; leakpath's hot loops do not use BLAS, so those are set for any child processes.

    The worker's standard output and error go to ``/dev/null``: a worker must not keep the
    driver's (a pipe its caller may be reading to the end) open. Results and errors travel
    back through the pool.

    With ``alive`` (see :func:`_watch_driver`), a daemon thread ends the worker as soon as
    the driver dies (a killed driver cannot shut its pool down; the workers would otherwise
    wait for work forever).
    """
    for name in _THREAD_ENV:
        os.environ[name] = str(int(threads))
    _detach_stdio()
    if alive is not None:
        import threading

        threading.Thread(
            target=_watch_driver, args=(alive,), name="leakpath-driver-watch", daemon=True
        ).start()


def _flush_std_streams() -> None:
    """Flush Python's stdout and stderr before their file descriptors are redirected."""
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):
            pass


def _detach_stdio() -> None:
    """Point file descriptors 1 and 2 of this process at ``/dev/null``."""
    _flush_std_streams()
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in (1, 2):
            os.dup2(devnull, fd)
    finally:
        os.close(devnull)


class _StartingChildren:
    """While the pool starts its helper processes (fork server, resource tracker, workers):

    * fds 1 and 2 point at ``/dev/null``, so none of them inherits the driver's standard
      output or error — a killed driver's caller reading them through a pipe then sees
      end-of-file at once;
    * ``__main__`` hides its path, unless the generator is a function defined there:
      ``spawn``/``forkserver`` children would otherwise run the calling program again as
      their main module — which fails when it is not a file (``python -``, a piped script,
      an interactive session) and starts the ensemble again in every worker when a script
      lacks the ``if __name__ == "__main__"`` guard. The tasks need nothing else from it.
    """

    def __init__(self, keep_main: bool = False) -> None:
        self.keep_main = keep_main

    def __enter__(self) -> _StartingChildren:
        self.saved: list[tuple[int, int]] = []
        _flush_std_streams()
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in (1, 2):
                try:
                    self.saved.append((fd, os.dup(fd)))
                except OSError:
                    continue
                os.dup2(devnull, fd)
        finally:
            os.close(devnull)
        self.main = sys.modules.get("__main__")
        self.main_file = getattr(self.main, "__file__", None)
        self.hidden = (
            not self.keep_main
            and self.main is not None
            and self.main_file is not None
            and getattr(self.main, "__spec__", None) is None
        )
        if self.hidden:
            del self.main.__file__
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.hidden:
            self.main.__file__ = self.main_file
        for fd, copy in self.saved:
            os.dup2(copy, fd)
            os.close(copy)


# ============================================================================ file layout


def _cpus() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))  # type: ignore[attr-defined]
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)


def _mp_context() -> multiprocessing.context.BaseContext:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _is_dask_client(obj: Any) -> bool:
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(obj, Client)


def _dask_client(address: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise ImportError(
            "executor: a Dask scheduler address needs dask.distributed; "
            "install it with pip install 'leakpath[dask]'"
        ) from None
    return Client(address)


class _Driver:
    """Bookkeeping shared by the executors: write finished tasks, count, report progress."""

    def __init__(
        self,
        out: Path,
        run_id: str,
        total: int,
        done_before: int,
        progress: bool,
        stop_after: int | None = None,
        record: OutputRecord | None = None,
    ):
        self.out = out
        self.run_id = run_id
        self.record = record
        self._unsaved = 0
        self.written: list[tuple[str, int]] = []
        self.failed: list[tuple[str, int, str]] = []
        self.compute_seconds = 0.0
        self.stop_after = stop_after
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(
                total=total,
                initial=done_before,
                desc="ensemble",
                unit="task",
                file=sys.stderr,
                disable=None,
                dynamic_ncols=True,
            )

    def done(self, result: _TaskOutput) -> None:
        paths = _write_task(self.out, result, self.run_id)
        if self.record is not None:
            # Saving the whole record after every task would cost quadratic time over
            # thousands of tasks; save it in growing batches instead. Task files a killed
            # driver did not record are still recognised by their checksums.
            self.record.add(paths, save=False)
            self._unsaved += 1
            if self._unsaved >= max(8, len(self.record.files) // 8):
                self.record.save()
                self._unsaved = 0
        self.written.append((result.key, result.seed))
        self.compute_seconds += result.seconds
        if self.bar is not None:
            self.bar.update(1)
        if self.stop_after is not None and len(self.written) >= self.stop_after:
            # test hook: an interrupted driver (no clean-up at all)
            os.kill(os.getpid(), getattr(signal, "SIGKILL", signal.SIGTERM))

    def error(self, spec: _TaskSpec, exc: BaseException) -> None:
        self.fail(spec, f"{type(exc).__name__}: {exc}")

    def fail(self, spec: _TaskSpec, reason: str) -> None:
        self.failed.append((spec.key, spec.seed, reason))
        if self.bar is not None:
            self.bar.update(1)

    def close(self) -> None:
        if self.record is not None and self._unsaved:
            self.record.save()
            self._unsaved = 0
        if self.bar is not None:
            self.bar.close()


def _run_serial(specs: list[_TaskSpec], driver: _Driver) -> dict[str, Any]:
    for spec in specs:
        try:
            result = _run_task(spec)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - reported per task
            driver.error(spec, exc)
        else:
            driver.done(result)
    return {"executor": "serial", "workers": 1}


def _run_processes(
    specs: list[_TaskSpec], driver: _Driver, workers: int, threads: int, retries: int
) -> dict[str, Any]:
    """Local process pool; a broken pool is replaced and the unfinished tasks resubmitted."""
    ctx = _mp_context()
    pending = {(s.key, s.seed): s for s in specs}
    # Workers watch the read end; only this process holds the write end (see _watch_driver).
    alive_r, alive_w = ctx.Pipe(duplex=False)
    try:
        return _run_pools(ctx, pending, driver, workers, threads, retries, alive_r)
    finally:
        alive_r.close()
        alive_w.close()


def _run_pools(
    ctx: Any,
    pending: dict[tuple[str, int], _TaskSpec],
    driver: _Driver,
    workers: int,
    threads: int,
    retries: int,
    alive: Any,
) -> dict[str, Any]:
    """Run the tasks on one process pool; if a worker process dies, the pool breaks and
    takes every unfinished task with it — those then run one process each
    (:func:`_run_isolated`), so that a task that kills its worker fails alone."""
    restarts = 0
    generator = next(iter(pending.values())).generator
    keep_main = getattr(generator, "__module__", None) == "__main__"
    # Worker processes start while the pool is built and tasks are submitted.
    with _StartingChildren(keep_main):
        pool = ProcessPoolExecutor(
            max_workers=min(workers, len(pending)),
            mp_context=ctx,
            initializer=_init_worker,
            initargs=(threads, alive),
        )
    clean = False
    try:
        with _StartingChildren(keep_main):
            futures = {pool.submit(_run_task, spec): tid for tid, spec in pending.items()}
        not_done = set(futures)
        while not_done:
            done, not_done = wait(not_done, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=lambda f: futures[f]):
                tid = futures[fut]
                try:
                    result = fut.result()
                except BrokenProcessPool:
                    continue  # stays pending
                except Exception as exc:  # noqa: BLE001 - the task's own error
                    driver.error(pending.pop(tid), exc)
                    continue
                driver.done(result)
                pending.pop(tid)
        clean = True
    finally:
        # After Ctrl-C or an error in the driver do not wait for running tasks.
        pool.shutdown(wait=clean, cancel_futures=True)
    isolated = len(pending)
    if pending:
        restarts = 1
        _run_isolated(ctx, pending, driver, workers, threads, retries, alive, keep_main)
    return {
        "executor": "processes",
        "start_method": ctx.get_start_method(),
        "workers": workers,
        "threads_per_worker": threads,
        "pool_restarts": restarts,
        "isolated_tasks": isolated,
    }


def _isolated_task(spec: _TaskSpec, conn: Any, threads: int, alive: Any) -> None:
    """Body of a one-task process: run the task, send ``("ok", output)`` or
    ``("error", reason)`` through ``conn``."""
    _init_worker(threads, alive)
    try:
        message: tuple[str, Any] = ("ok", _run_task(spec))
    except BaseException as exc:  # noqa: BLE001 - reported as the task's failure
        message = ("error", f"{type(exc).__name__}: {exc}")
    conn.send(message)
    conn.close()


def _death_reason(exitcode: int | None) -> str:
    """Why a worker process ended without a result, from its exit code."""
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"its worker process was killed by {name}"
    return f"its worker process exited with status {exitcode} without a result"


def _run_isolated(
    ctx: Any,
    pending: dict[tuple[str, int], _TaskSpec],
    driver: _Driver,
    workers: int,
    threads: int,
    retries: int,
    alive: Any,
    keep_main: bool,
) -> None:
    """Run each pending task in a process of its own, ``workers`` at a time.

    A task whose process dies is run again up to ``retries`` times, then reported failed
    with the reason (signal or exit status); every other task is written as it finishes.
    """
    queue = list(pending)
    deaths = dict.fromkeys(pending, 0)
    running: dict[Any, tuple[tuple[str, int], Any]] = {}  # result pipe → (task, process)
    try:
        while queue or running:
            while queue and len(running) < workers:
                tid = queue.pop(0)
                read, write = ctx.Pipe(duplex=False)
                proc = ctx.Process(
                    target=_isolated_task,
                    args=(pending[tid], write, threads, alive),
                    name=f"leakpath-task-{tid[0]}-seed-{tid[1]}",
                    daemon=True,
                )
                with _StartingChildren(keep_main):
                    proc.start()
                write.close()  # the child's copy is the only one: EOF when it dies
                running[read] = (tid, proc)
            for conn in _wait_ready(list(running)):
                tid, proc = running.pop(conn)
                try:
                    status, payload = conn.recv()
                except (EOFError, OSError):
                    status, payload = "died", None
                finally:
                    conn.close()
                proc.join()
                if status == "ok":
                    pending.pop(tid)
                    driver.done(payload)
                elif status == "error":
                    driver.fail(pending.pop(tid), str(payload))
                else:
                    deaths[tid] += 1
                    if deaths[tid] > retries:
                        driver.fail(pending.pop(tid), _death_reason(proc.exitcode))
                    else:
                        queue.append(tid)
    finally:
        for conn, (_, proc) in running.items():  # only after an error in the driver
            proc.kill()
            proc.join()
            conn.close()


def _run_dask(
    client: Any, specs: list[_TaskSpec], driver: _Driver, retries: int, threads: int | None
) -> dict[str, Any]:
    """Submit every task to a Dask cluster; write each result as it arrives."""
    from distributed import as_completed

    token = os.urandom(4).hex()
    futures = {}
    for spec in specs:
        fut = client.submit(
            _run_task_dask,
            spec,
            threads,
            key=f"leakpath-ensemble-{token}-{spec.key}-seed-{spec.seed}",
            pure=False,
            retries=retries,
        )
        futures[fut.key] = (fut, spec)
    try:
        for fut in as_completed([f for f, _ in futures.values()]):
            spec = futures[fut.key][1]
            if fut.status == "finished":
                driver.done(fut.result())
            else:
                try:
                    exc = fut.exception()
                except BaseException as err:  # noqa: BLE001 - e.g. CancelledError
                    exc = err
                driver.error(spec, exc if exc is not None else RuntimeError(fut.status))
            fut.release()
    except BaseException:
        for fut, _ in futures.values():
            fut.cancel()
        raise
    try:
        info = client.scheduler_info()
        n_workers = len(info.get("workers", {}))
        total = sum(int(w.get("nthreads", 0)) for w in info.get("workers", {}).values())
    except Exception:  # noqa: BLE001 - informational only
        n_workers = total = None
    return {
        "executor": "dask",
        "scheduler": getattr(getattr(client, "scheduler", None), "address", None),
        "workers": n_workers,
        "dask_threads": total,
        "rayon_threads_per_task": threads if threads is not None else "1 (or worker env)",
        "retries": retries,
    }


# ============================================================================ validation
