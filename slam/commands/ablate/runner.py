"""Running an ablation's jobs on a local process pool or on Ray, resumably.

Output folder ``OUT``:

* ``OUT/inputs/<scenario>-<hash>-seed<N>/``: each simulated input, once;
* ``OUT/jobs/<id>/``: each job's result folder, as ``gslam map`` writes it;
* ``OUT/failed/<id>.json``: the one-line error of a job that failed;
* ``OUT/spec.yaml``, ``OUT/summary.csv``, ``OUT/summary.md``, ``OUT/plots/``,
  ``OUT/report.html`` (``output.report`` of the spec's config).

Jobs that read and scan-match the same thing run together in one worker
and share that work (:mod:`slam.commands.ablate.sharing`).

``OUT`` must be new or an earlier sweep folder (:func:`slam.results.outdir.open_container`).
Every folder and file is written beside its place and renamed into it, so a
job is finished exactly when ``jobs/<id>/metrics.json`` exists, whatever
moment the sweep was killed at. Running the same spec again skips finished
jobs and retries failed ones. A lock on ``OUT/.lock`` keeps two sweeps out
of one folder (the kernel drops it when a process dies, even by kill -9).
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import shutil
import threading
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import yaml
from tqdm import tqdm

from slam.commands.ablate.jobs import Job, expand_jobs
from slam.commands.ablate.sharing import run_jobs, share_groups
from slam.commands.ablate.spec import AblationSpec
from slam.commands.ablate.worker import FileLock, JobOutcome, is_finished
from slam.errors import GslamError
from slam.results.atomic import write_text
from slam.results.out_checks import resolve_path
from slam.results.outdir import TEMP_TAG, open_container

CONTAINER_NAMES = (
    "spec.yaml", "summary.csv", "summary.md", "report.html", ".lock", "plots/", "inputs/", "jobs/", "failed/",
)
"""What a sweep writes into its folder (each job's result inside ``jobs/``)."""

log = logging.getLogger(__name__)


class Backend(str, Enum):
    """Where jobs run: a local process pool, or tasks on a Ray cluster."""

    LOCAL = "local"
    RAY = "ray"


@dataclass
class AblationResult:
    """What a sweep did: every job of the spec, which ran now, which were
    already finished and skipped, which failed (id -> error) and the wall
    time of the whole command (s)."""

    out_dir: Path
    jobs: list[Job]
    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    outcomes: list[JobOutcome] = field(default_factory=list)
    wall_s: float = 0.0
    summary: Any = None


def dispatch_order(jobs: list[Job]) -> list[Job]:
    """Jobs round-robin over their inputs, so workers starting together
    simulate different inputs instead of waiting for the same one."""
    rank: dict[str, int] = {}
    keyed = []
    for i, job in enumerate(jobs):
        key = job.simulated.key if job.simulated is not None else str(job.input_path)
        keyed.append((rank.get(key, 0), i, job))
        rank[key] = rank.get(key, 0) + 1
    return [job for _, _, job in sorted(keyed, key=lambda k: (k[0], k[1]))]


def _quiet_worker() -> None:
    # A worker's warnings (e.g. a run without GPS fixes) would repeat once per
    # job and break the progress bar; errors end up in failed/<id>.json.
    logging.basicConfig(level=logging.ERROR, format="%(levelname)s %(name)s: %(message)s")


def _pool_worker() -> None:
    """Initializer of a local worker: quiet, and gone when the sweep is
    (a pool worker outlives a parent killed with -9; its half-written
    folder is removed by the next run). tqdm's lock is a thread lock
    here: its default, a named semaphore, would be reported leaked when an
    interrupted sweep ends its workers (their bars are never shown)."""
    from tqdm import tqdm

    _quiet_worker()
    tqdm.set_lock(threading.RLock())
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()


def _exit_with_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(1.0)
    os._exit(1)


# --- backends --------------------------------------------------------------------


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def _threads_per_worker(n: int) -> Iterator[None]:
    """Environment of the workers spawned inside: numeric libraries use
    ``n`` threads, unless the user set them. Without this, every worker's
    BLAS starts one thread per core and two workers on two cores run 18 %
    slower each (measured) than one."""
    saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
    for k in THREAD_VARIABLES:
        os.environ.setdefault(k, str(n))
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _local(groups: list[list[Job]], out_dir: Path, workers: int) -> Iterator[JobOutcome]:
    # spawn: forking a parent that has loaded gtsam/open3d threads is unsafe.
    ctx = multiprocessing.get_context("spawn")
    threads = max(1, (os.cpu_count() or 1) // workers)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_pool_worker)
    try:
        with _threads_per_worker(threads):  # workers start on the first submits
            pending = {pool.submit(run_jobs, group, str(out_dir)): group for group in groups}
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                group = pending.pop(fut)
                try:
                    yield from fut.result()
                except Exception as e:  # noqa: BLE001 - e.g. a worker killed by a crash
                    error = f"{type(e).__name__}: {e}".splitlines()[0]
                    yield from (JobOutcome(job.id, error, 0.0) for job in group)
    except BaseException:
        _interrupt_workers(pool)
        _clean_leftovers(out_dir)  # what the workers were writing, now that none lives
        raise
    pool.shutdown(wait=True)


def _interrupt_workers(pool: ProcessPoolExecutor) -> None:
    """Stop a pool whose sweep was interrupted without waiting for its
    jobs: Ctrl-C reaches the workers from the terminal, the other signals
    only this process. The caller then removes what their jobs left half
    written; the next run runs the unfinished jobs again."""
    workers = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in workers:
        process.terminate()
    for process in workers:
        process.join()


RAY_CONNECT_TIMEOUT_S = 10.0
"""How long a Ray cluster's address has to answer before ``--address`` is refused."""


def check_reachable(address: str, timeout_s: float = RAY_CONNECT_TIMEOUT_S) -> None:
    """A one-line error unless something listens at a ``host:port`` address
    (``ray://host:port`` too) within ``timeout_s``: Ray itself would wait
    for minutes. ``auto`` and other forms are left to Ray."""
    import socket

    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as e:
        why = "no answer" if isinstance(e, TimeoutError) else (e.strerror or str(e))
        raise GslamError(f"--address {address}: no Ray cluster answers there ({why} within {timeout_s:g} s); "
                         "start one (ray start --head) or check the address") from None


def _ray(groups: list[list[Job]], out_dir: Path, workers: int, address: str | None) -> Iterator[JobOutcome]:
    try:
        import ray
    except ImportError:
        raise GslamError('the Ray backend needs ray: pip install ".[ray]"') from None
    started = not ray.is_initialized()
    if started:
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
        if address is None:
            kwargs["num_cpus"] = workers
        ray.init(address=address, **kwargs)
    try:
        task = ray.remote(num_cpus=1)(_ray_jobs)
        pending = {task.remote(group, str(out_dir)): group for group in groups}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                group = pending.pop(ref)
                try:
                    yield from ray.get(ref)
                except Exception as e:  # noqa: BLE001 - a task lost with its node
                    error = f"{type(e).__name__}: {e}".splitlines()[0]
                    yield from (JobOutcome(job.id, error, 0.0) for job in group)
    finally:
        if started:
            ray.shutdown()


def _ray_jobs(jobs: list[Job], out_dir: str) -> list[JobOutcome]:
    _quiet_worker()
    return run_jobs(jobs, out_dir)


# --- the sweep -------------------------------------------------------------------


def run_ablation(
    spec: AblationSpec,
    out_dir: str | Path,
    workers: int | None = None,
    backend: Backend | str = Backend.LOCAL,
    address: str | None = None,
    progress: bool = True,
    source: str = "spec",
    on_outcome: Callable[[JobOutcome], None] | None = None,
    force: bool = False,
) -> AblationResult:
    """Run every unfinished job of ``spec`` into ``out_dir`` and summarise
    (the library form of ``gslam ablate``). ``workers``: parallel jobs
    (default: CPU count); ``address``: a Ray cluster (``auto``), or None for
    a local Ray instance; ``force``: see :mod:`slam.results.outdir`."""
    from slam.commands.ablate.summary import write_summary

    t0 = time.perf_counter()
    backend = Backend(backend)
    jobs = expand_jobs(spec, source)  # validates everything before any job runs
    if backend is Backend.RAY and address is not None:
        check_reachable(address)
    inputs = [source, spec.config, *(s.path for s in spec.inputs.scenarios)]
    inputs += [j.input_path for j in jobs if j.input_path is not None]
    out_dir = resolve_path(open_container(out_dir, "ablate", inputs, force, CONTAINER_NAMES))
    workers = max(1, workers or os.cpu_count() or 1)
    with FileLock(out_dir / ".lock"):
        _clean_leftovers(out_dir)
        write_text(out_dir / "spec.yaml", yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False))
        result = AblationResult(out_dir, jobs)
        todo: list[Job] = []
        for job in jobs:
            if is_finished(out_dir, job):
                result.skipped.append(job.id)
            else:
                todo.append(job)
        log.info("%d jobs: %d finished before, %d to run on %s x%d", len(jobs), len(result.skipped), len(todo), backend.value, workers)
        if todo:
            groups = share_groups(dispatch_order(todo), workers)
            runner = _local(groups, out_dir, workers) if backend is Backend.LOCAL else _ray(groups, out_dir, workers, address)
            # disable=None: a bar only on a terminal, never into a piped log.
            shown = None if progress else True
            with tqdm(total=len(jobs), initial=len(result.skipped), unit="job", desc="ablate", disable=shown) as bar:
                for outcome in runner:
                    result.outcomes.append(outcome)
                    if outcome.error is None:
                        result.ran.append(outcome.id)
                    else:
                        result.failed[outcome.id] = outcome.error
                        log.warning("job %s failed: %s", outcome.id, outcome.error)
                    if on_outcome is not None:
                        on_outcome(outcome)
                    bar.set_postfix(failed=len(result.failed))
                    bar.update(1)
        result.summary = write_summary(out_dir, jobs, spec, wants_report(spec))
    result.wall_s = time.perf_counter() - t0
    return result


def wants_report(spec: AblationSpec) -> bool:
    """``output.report`` of the spec's config, or of its ``set``."""
    from slam.config import load_config

    if "output.report" in spec.set:
        return bool(spec.set["output.report"])
    return load_config(spec.config).output.report


def _clean_leftovers(out_dir: Path) -> None:
    """Remove the temporary folders and files of a sweep that was killed:
    every writer builds ``.<name>.gslam-tmp-*`` beside its target, and the
    sweep's lock means no live process still writes them. Other names are
    left alone."""
    for sub in ("inputs", "jobs", "failed"):
        d = out_dir / sub
        if not d.is_dir():
            continue
        for p in d.iterdir():
            if p.name.startswith(".") and TEMP_TAG in p.name and not p.is_symlink():
                log.info("removing leftover %s", p)
                shutil.rmtree(p) if p.is_dir() else p.unlink()
