"""Scripted ablation experiments (``gslam ablate``): sweeps over configs,
scenarios and seeds, run in parallel on a local process pool or on Ray,
resumable, and summarised into one table and figures.

A spec (:mod:`slam.commands.ablate.spec`) expands into jobs (:mod:`slam.commands.ablate.jobs`),
each a normal ``gslam map`` result folder; :mod:`slam.commands.ablate.runner` runs the
unfinished ones, each in a worker (:mod:`slam.commands.ablate.worker`), and
:mod:`slam.commands.ablate.summary` combines the folders.
"""

from slam.commands.ablate.jobs import Job, expand_jobs
from slam.commands.ablate.runner import AblationResult, Backend, run_ablation
from slam.commands.ablate.spec import AblationSpec, load_spec
from slam.commands.ablate.summary import Summary, write_summary
from slam.commands.ablate.worker import JobOutcome, run_job

__all__ = [
    "AblationResult", "AblationSpec", "Backend", "Job", "JobOutcome", "Summary",
    "expand_jobs", "load_spec", "run_ablation", "run_job", "write_summary",
]
