"""One job of a sweep, as a worker process runs it: simulate its input if
needed, map it into ``OUT/jobs/<id>/``, and record a failure instead of
raising, so that a failing job never stops the sweep."""

from __future__ import annotations

import fcntl
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

from slam.commands.ablate.jobs import Job, SimulatedInput
from slam.errors import GslamError
from slam.results.atomic import write_text


@dataclass(frozen=True)
class JobOutcome:
    """What one job did: ``error`` is None on success; ``time_s`` is the
    wall time in the worker (s), ``simulate_s`` the part spent simulating."""

    id: str
    error: str | None
    time_s: float
    simulate_s: float = 0.0


def is_finished(out_dir: Path, job: Job) -> bool:
    return (out_dir / "jobs" / job.id / "metrics.json").exists()


def ensure_input(out_dir: Path, sim: SimulatedInput) -> float:
    """Simulate ``sim`` into ``out_dir/inputs/<key>/`` unless it is there;
    the wall time spent (s). The simulator builds it beside its place and
    renames it in."""
    from slam.sim import simulate_scenario
    from slam.sim.scenario import Scenario

    target = out_dir / "inputs" / sim.key
    if (target / "truth.json").exists():
        return 0.0
    t = time.perf_counter()
    target.parent.mkdir(parents=True, exist_ok=True)
    # Workers wanting the same input wait for the first rather than
    # simulating it twice.
    with FileLock(target.parent / f".{sim.key}.lock", blocking=True):
        if not (target / "truth.json").exists():
            simulate_scenario(Scenario.model_validate(sim.scenario), target)
    return time.perf_counter() - t


def run_job(job: Job, out_dir: str | Path) -> JobOutcome:
    """Run one job into ``out_dir/jobs/<id>/``; never raises for a failing
    job: its error goes to ``out_dir/failed/<id>.json`` and the outcome."""
    from slam.config import load_config
    from slam.pipeline.folder import run_map

    out_dir = Path(out_dir)
    t = time.perf_counter()
    failed = out_dir / "failed" / f"{job.id}.json"
    sim_s = 0.0
    try:
        if job.simulated is not None:
            sim_s = ensure_input(out_dir, job.simulated)
        config = load_config(job.config_path, list(job.overrides))
        run_map(job.input_dir(out_dir), config, out_dir / "jobs" / job.id)
    except Exception as e:  # noqa: BLE001 - a failing job must not stop the sweep
        error = record_failure(out_dir, job, e)
        return JobOutcome(job.id, error, time.perf_counter() - t, sim_s)
    failed.unlink(missing_ok=True)
    return JobOutcome(job.id, None, time.perf_counter() - t, sim_s)


def record_failure(out_dir: Path, job: Job, e: Exception) -> str:
    """Write ``out_dir/failed/<id>.json`` with the one-line error; return it."""
    error = f"{type(e).__name__}: {e}".splitlines()[0]
    write_text(out_dir / "failed" / f"{job.id}.json", json.dumps({"id": job.id, "error": error}, indent=2) + "\n")
    return error


class FileLock:
    """An exclusive ``flock`` on ``path`` (released when the process ends,
    however it ends). Not blocking: a held lock raises GslamError."""

    def __init__(self, path: Path, blocking: bool = False):
        self.path = path
        self.blocking = blocking
        self.fd: int | None = None

    def __enter__(self) -> "FileLock":
        self.fd = os.open(self.path, os.O_CREAT | os.O_RDWR, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | (0 if self.blocking else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(self.fd)
            raise GslamError(f"{self.path.parent}: another gslam ablate is running on this folder") from None
        return self

    def __exit__(self, *exc: object) -> None:
        if self.fd is not None:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
