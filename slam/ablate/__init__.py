"""Scripted ablation experiments (``gslam ablate``): sweeps over configs,
scenarios and seeds, run in parallel on a local process pool or on Ray,
resumable, and summarised into one table and figures.

A spec (:mod:`slam.ablate.spec`) expands into jobs (:mod:`slam.ablate.jobs`),
each a normal ``gslam map`` result folder; :mod:`slam.ablate.runner` runs the
unfinished ones, each in a worker (:mod:`slam.ablate.worker`), and
:mod:`slam.ablate.summary` combines the folders.
"""

from slam.ablate.jobs import Job, expand_jobs
from slam.ablate.runner import AblationResult, Backend, run_ablation
from slam.ablate.spec import AblationSpec, load_spec
from slam.ablate.summary import Summary, write_summary
from slam.ablate.worker import JobOutcome, run_job

__all__ = [
    "AblationResult", "AblationSpec", "Backend", "Job", "JobOutcome", "Summary",
    "expand_jobs", "load_spec", "run_ablation", "run_job", "write_summary",
]
