"""Jobs of a sweep that read and scan-match the same thing, run together.

Most sweeps vary the validation, gating or back-end and keep the input and
the front-end: every such job would read the same bag and run KISS-ICP on
the same scans again, which is most of a job's time. :func:`share_groups`
puts jobs whose reading and scan matching are the same (same input, same
``input``, ``frontend`` and ``evaluation`` sections, scan matching on or
off alike) into groups, and :func:`run_jobs` runs a group in one worker:
the first job reads and matches, the others reuse its recording and
front-end, as ``gslam compare`` does for its variants. Each job still
writes its own result folder, atomically, so a killed sweep resumes job
by job. A later job's ``runtime_s`` does not count the reading and scan
matching it reused (its ``timings_s`` show ``read`` and ``frontend`` 0).

Groups are split so that there are at least twice as many groups as
workers where the jobs allow, to keep every worker busy to the end.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

from slam.commands.ablate.jobs import Job
from slam.commands.ablate.worker import JobOutcome, ensure_input, record_failure


def sharing_key(job: Job, config) -> str:
    """What a job's reading and scan matching depend on."""
    source = job.simulated.key if job.simulated is not None else str(job.input_path)
    parts = {
        "input": source,
        "reader": config.input.model_dump(mode="json"),
        "frontend": config.frontend.model_dump(mode="json"),
        "evaluation": config.evaluation.model_dump(mode="json"),  # labels the front-end's faults in the recording
        "scan_matching": config.backend.factors.scan_matching.enabled,
    }
    return json.dumps(parts, sort_keys=True)


def share_groups(jobs: list[Job], workers: int) -> list[list[Job]]:
    """``jobs`` in groups that share reading and scan matching, in the
    order of their first job; each group split into pieces so that there
    are about ``2 * workers`` pieces in all (never pieces of one job more
    than the jobs need)."""
    from slam.config import load_config

    configs: dict[tuple[str, tuple[str, ...]], object] = {}
    groups: dict[str, list[Job]] = {}
    for job in jobs:
        ck = (job.config_path, job.overrides)
        if ck not in configs:
            configs[ck] = load_config(job.config_path, list(job.overrides))
        groups.setdefault(sharing_key(job, configs[ck]), []).append(job)
    pieces: list[list[Job]] = []
    for group in groups.values():
        n = min(len(group), max(1, math.ceil(len(group) * 2 * workers / len(jobs))))
        size = math.ceil(len(group) / n)
        pieces += [group[i : i + size] for i in range(0, len(group), size)]
    return pieces


def run_jobs(jobs: list[Job], out_dir: str | Path) -> list:
    """Run ``jobs`` (one group) one after the other into ``out_dir``,
    reusing the first successful job's recording and front-end; a failing
    job is recorded as :func:`slam.commands.ablate.worker.run_job` records it and
    the others continue."""
    from slam.config import load_config
    from slam.pipeline.folder import MappingPipeline

    out_dir = Path(out_dir)
    outcomes = []
    recording = frontend = None
    for job in jobs:
        t = time.perf_counter()
        sim_s = 0.0
        try:
            if job.simulated is not None:
                sim_s = ensure_input(out_dir, job.simulated)
            config = load_config(job.config_path, list(job.overrides))
            pipe = MappingPipeline(job.input_dir(out_dir), config, out_dir / "jobs" / job.id,
                                   recording=recording, frontend=frontend)
            pipe.run()
            recording, frontend = pipe.recording, pipe.frontend
        except Exception as e:  # noqa: BLE001 - a failing job must not stop the sweep
            error = record_failure(out_dir, job, e)
            outcomes.append(JobOutcome(job.id, error, time.perf_counter() - t, sim_s))
            continue
        (out_dir / "failed" / f"{job.id}.json").unlink(missing_ok=True)
        outcomes.append(JobOutcome(job.id, None, time.perf_counter() - t, sim_s))
    return outcomes
