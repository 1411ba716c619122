"""Unary plausibility checks: one component against physics.

A *unary* check tests one component against physics (the magnetometer's
field strength and dip against the local Earth field, its vector's turn
against the gyro's, the GPS receiver's reported sigma); it says ``IMPLAUSIBLE`` once the deviation has lasted
``hold_s`` and ``PLAUSIBLE`` otherwise. :func:`unary_checks` builds the
enabled checks from :class:`~validation.observer_config.ObserversConfig`;
:func:`held` applies the hold time over a whole run.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from validation.observer_config import ObserversConfig

logger = logging.getLogger(__name__)

_HOLD_EPS_S = 1e-9  # step times are sums of floats; 0.1 * 10 may land below 1.0


class MagneticReference(Protocol):
    """The undisturbed local Earth field: strength (T) and dip (rad, positive down)."""

    strength_T: float
    dip_rad: float


@dataclass(frozen=True)
class MagnetometerCheck:
    """Field strength (T) and dip (rad, positive down) against the Earth field."""

    name: str
    component: str
    strength_T: float
    dip_rad: float
    tolerance_T: float
    tolerance_dip_rad: float
    hold_s: float
    streams: tuple[str, ...] = ("mag_strength", "mag_dip")

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where the field differs from the reference beyond a tolerance."""
        return (np.abs(values["mag_strength"] - self.strength_T) > self.tolerance_T) | (
            np.abs(values["mag_dip"] - self.dip_rad) > self.tolerance_dip_rad
        )


@dataclass(frozen=True)
class FieldGyroCheck:
    """The field's change the gyro's turn does not explain (T) against a
    tolerance (:mod:`validation.field_gyro`)."""

    name: str
    component: str
    tolerance_T: float
    hold_s: float
    streams: tuple[str, ...] = ("mag_field_change",)

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where the field changed beyond the tolerance."""
        return np.asarray(values["mag_field_change"]) > self.tolerance_T


@dataclass(frozen=True)
class GpsQualityCheck:
    """The receiver's horizontal sigma (m) against a maximum."""

    name: str
    component: str
    max_sigma_m: float
    hold_s: float
    streams: tuple[str, ...] = ("gps_sigma",)

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where the reported sigma exceeds the maximum."""
        return np.asarray(values["gps_sigma"]) > self.max_sigma_m


UnaryCheck = MagnetometerCheck | FieldGyroCheck | GpsQualityCheck


def unary_checks(config: ObserversConfig, reference: MagneticReference | None = None) -> list[UnaryCheck]:
    """The enabled unary checks; the magnetometer check needs a reference
    field (config values first, then ``reference``) and is skipped without."""
    checks: list[UnaryCheck] = []
    mag = config.magnetometer
    if mag.enabled:
        strength, dip = (reference.strength_T, reference.dip_rad) if reference is not None else (None, None)
        if mag.strength_T is not None:
            strength = mag.strength_T
        if mag.dip_deg is not None:
            dip = np.radians(mag.dip_deg)
        if strength is None or dip is None:
            logger.warning("no magnetic reference field: the magnetometer check is off")
        else:
            checks.append(
                MagnetometerCheck(
                    mag.name, mag.component, float(strength), float(dip),
                    mag.tolerance_T, float(np.radians(mag.tolerance_dip_deg)), mag.hold_s,
                )
            )
    fg = config.field_gyro
    if fg.enabled:
        checks.append(FieldGyroCheck(fg.name, fg.component, fg.tolerance_T, fg.hold_s))
    if config.gps.enabled:
        g = config.gps
        checks.append(GpsQualityCheck(g.name, g.component, g.max_sigma_m, g.hold_s))
    return checks


def held(t: np.ndarray, deviant: np.ndarray, hold_s: float) -> np.ndarray:
    """True where ``deviant`` has been true on every step for at least ``hold_s``
    (measured from the first step of the run; ``hold_s = 0`` flags at once)."""
    n = len(t)
    idx = np.arange(n)
    starts = deviant & ~np.concatenate(([False], deviant[:-1]))
    run_start = np.maximum.accumulate(np.where(starts, idx, 0)) if n else idx
    return deviant & (t - t[run_start] >= hold_s - _HOLD_EPS_S)
