"""Whether a config fits the recording it maps: the checks that need both,
made once the recording is read and before any work on it.

* **The laser** within the front-end's limits (``frontend.min_range_m``,
  ``max_range_m``): if no scan keeps a return, the laser returns nothing
  for this config, a warning, and scan matching is left out (no
  scan-matching factor from an empty scan).
* **The voxel size** against the scans: KISS-ICP needs voxels somewhat
  smaller than the scene. Measured on the simulated lab run (clean, median
  return 2.7 m): ATE 0.05 m at 0.1 m voxels, 0.27 m at 1 m, 6.4 m at
  0.01 m (and 5 times the time), 9.8 m at 5 m. So a voxel below a
  hundredth of the median return or above a third of it is a warning, and
  below a thousandth or above twice the median return an error. The shipped
  configs keep between an eighth and a 27th of it on every real log.
* **Validation windows** (``validation.rate_hz``, each relation's
  ``window_s``) against the run's duration: a window longer than the run
  never fills, one shorter than two validation steps holds no trend: both
  would leave an observer that silently does nothing, so they are errors.
* **Factors left**: an enabled factor whose stream the recording lacks adds
  nothing; if no enabled factor has its stream, there is no graph: an error.
"""

from __future__ import annotations

import logging

import numpy as np

from slam.config import PipelineConfig, enabled_factors, validation_sections
from slam.errors import GslamError
from slam.frontend.kiss import ScanProjector
from slam.recording import Recording
from validation.base.modes import GatingMode

log = logging.getLogger(__name__)

VOXEL_WARN = (1 / 100, 1 / 3)
"""Voxel size per median return beyond which registration degrades (a warning)."""
VOXEL_ERROR = (1 / 1000, 2.0)
"""Voxel size per median return beyond which it fails (an error)."""
MAX_STEPS = 10_000_000
"""Most validation steps of a run (a day at 100 Hz)."""
SAMPLE_SCANS = 400
"""Scans looked at for the median return (evenly spread)."""

FACTOR_STREAMS = {"odometry": "odometry", "gyro": "gyro", "compass": "compass", "scan_matching": "scans", "gps": "gps"}


def check_fit(rec: Recording, config: PipelineConfig, source: object) -> None:
    """The checks of the module docstring; may leave the scans out of
    ``rec`` (in place)."""
    if config.frontend.enabled and config.backend.factors.scan_matching.enabled and rec.scans is not None:
        _check_laser(rec, config, source)
    _check_factors(rec, config, source)
    _check_windows(rec, config, source)


def _returns(rec: Recording, config: PipelineConfig) -> np.ndarray:
    """The ranges the front-end keeps, of an even sample of the scans."""
    fe, scans = config.frontend, rec.scans
    project = ScanProjector(scans.angles, fe.min_range_m, min(fe.max_range_m, scans.range_max))
    rows = np.unique(np.linspace(0, len(scans) - 1, min(len(scans), SAMPLE_SCANS)).astype(int))
    r = scans.ranges[rows].astype(np.float64)
    return r[project.keep(r)]


def _check_laser(rec: Recording, config: PipelineConfig, source: object) -> None:
    fe, scans = config.frontend, rec.scans
    kept = _returns(rec, config)
    if kept.size == 0:
        project = ScanProjector(scans.angles, fe.min_range_m, min(fe.max_range_m, scans.range_max))
        if not project.keep(scans.ranges).any():
            log.warning("%s: the laser returns nothing within frontend.min_range_m %g and max_range_m %g "
                        "(its range_max %g): scan matching left out, so no scan-matching factor",
                        source, fe.min_range_m, min(fe.max_range_m, scans.range_max), scans.range_max)
            rec.scans = None
            return
        kept = scans.ranges[project.keep(scans.ranges)].astype(np.float64)
    median = float(np.median(kept))
    ratio = fe.voxel_size_m / median
    what = f"frontend.voxel_size_m {fe.voxel_size_m:g} is {_fraction(ratio)} the median laser return ({median:.3g} m)"
    if not VOXEL_ERROR[0] <= ratio <= VOXEL_ERROR[1]:
        raise GslamError(f"{source}: {what}; KISS-ICP registers nothing useful there: expected about "
                         f"{median / 30:.2g} m (between {median * VOXEL_WARN[0]:.2g} and {median * VOXEL_WARN[1]:.2g})")
    if not VOXEL_WARN[0] <= ratio <= VOXEL_WARN[1]:
        log.warning("%s: %s; registration degrades outside %.2g to %.2g m", source, what,
                    median * VOXEL_WARN[0], median * VOXEL_WARN[1])


def _fraction(ratio: float) -> str:
    return f"{ratio:.3g} times" if ratio >= 1 else f"1/{1 / ratio:.3g} of"


def _check_factors(rec: Recording, config: PipelineConfig, source: object) -> None:
    enabled = enabled_factors(config)
    usable = [f for f in enabled if getattr(rec, FACTOR_STREAMS[f]) is not None]
    if usable:
        return
    has = [name for name in ("scans", "odometry", "gyro", "compass", "gps") if getattr(rec, name) is not None]
    raise GslamError(f"{source}: no factor left: the config enables {', '.join(enabled)}, whose streams the recording "
                     f"lacks (it has {', '.join(has) or 'none of them'}); enable a factor of a stream it has "
                     "(backend.factors)")


def _check_windows(rec: Recording, config: PipelineConfig, source: object) -> None:
    vcfg, _ = validation_sections(config)
    if vcfg.mode is GatingMode.OFF:
        return
    duration = rec.duration
    step = 1.0 / vcfg.rate_hz
    if duration * vcfg.rate_hz > MAX_STEPS:
        raise GslamError(f"{source}: validation.rate_hz {vcfg.rate_hz:g} makes {duration * vcfg.rate_hz:.3g} validation "
                         f"steps over the run's {duration:.3g} s, more than {MAX_STEPS:.0e}; expected a rate of a few Hz")
    if duration < 2 * step:
        raise GslamError(f"{source}: validation.rate_hz {vcfg.rate_hz:g} gives fewer than 2 validation steps over "
                         f"the run's {duration:.3g} s; expected a rate of a few Hz")
    for rel in vcfg.observers.relations:
        key = f"validation.observers.relations.{rel.name}.window_s"
        if rel.window_s > duration:
            raise GslamError(f"{source}: {key} {rel.window_s:g} s is longer than the run ({duration:.3g} s): "
                             "the observer would never compare its streams")
        if rel.window_s < 2 * step:
            raise GslamError(f"{source}: {key} {rel.window_s:g} s holds fewer than 2 validation steps "
                             f"(validation.rate_hz {vcfg.rate_hz:g}): no trend can be fitted")
