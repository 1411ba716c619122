"""Unary plausibility checks: one component against physics.

A *unary* check tests one component against physics (the magnetometer's
field strength and dip against the local Earth field, its vector's turn
against the gyro's, the GPS receiver's reported sigma, a laser scan's
returns and the conditioning of its registration); it says
``IMPLAUSIBLE`` once the deviation has lasted
``hold_s`` and ``PLAUSIBLE`` otherwise. :func:`unary_checks` builds the
enabled checks from :class:`~validation.observers.config.ObserversConfig`;
:func:`held` applies the hold time over a whole run.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from validation.observers.config import SCAN_AXES, ObserversConfig
from validation.streams import Stream

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
    tolerance (:mod:`validation.streams.field_gyro`)."""

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


class ScanGeometrySeries(Protocol):
    """The front-end's figures per scan: ``t`` (n,) s, ``returns`` (n,),
    ``min_eigenvalue`` (n,) of the normalised point-to-line information
    matrix and its unit eigenvector ``weak`` (n, 3) (forward, left, turn);
    the share of beams without a return ``no_return`` (n,), the returns
    bordering a gap ``gap_edges`` (n,), the share of those within a tenth
    of the farthest return ``edges_at_ceiling`` (n,) and that return
    ``farthest`` (n,) m; ``reach_m``, the farthest a return may lie."""

    t: np.ndarray
    returns: np.ndarray
    min_eigenvalue: np.ndarray
    weak: np.ndarray
    no_return: np.ndarray
    gap_edges: np.ndarray
    edges_at_ceiling: np.ndarray
    farthest: np.ndarray
    reach_m: float


@dataclass(frozen=True)
class ScanDegeneracyCheck:
    """One scan-matching modality (``axis`` 0 forward, 1 left, 2 turn)
    against the geometry of the scans it registers (Zhang, Kaess and Singh,
    ICRA 2016): too few returns, or the weakest direction of the
    point-to-line information is too weak and lies along ``axis``.

    Its stream is the verdict per scan, 1 or 0 (:meth:`flags`); on the
    validation steps between two scans it is interpolated, so every step
    between a degenerate scan and its neighbours is deviant: both scan
    matching motions that end or start at that scan."""

    name: str
    component: str
    axis: int
    min_returns: int
    min_eigenvalue: float
    min_share: float
    hold_s: float
    streams: tuple[str, ...] = ()

    def flags(self, geometry: ScanGeometrySeries) -> np.ndarray:
        """True for each scan that cannot constrain this modality."""
        few = np.asarray(geometry.returns) < self.min_returns
        weak = np.asarray(geometry.min_eigenvalue) < self.min_eigenvalue
        return few | (weak & (np.abs(np.asarray(geometry.weak)[:, self.axis]) > self.min_share))

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where a degenerate scan is at either end of the interval."""
        return np.asarray(values[self.streams[0]]) > 0.0


@dataclass(frozen=True)
class ScanCeilingCheck:
    """The whole scan matcher against a laser that sees too little: a scan
    cut off at a range ceiling (many beams without a return, and the gaps'
    edges at the scan's farthest return) cannot give scan matching the
    surfaces beyond it (:class:`~validation.observers.config.ScanCeilingConfig`).
    Scans between two cut-off ones at most ``fill_s`` apart are cut off too:
    a range limit persists. The scans of the ``settle_s`` after a cut that
    lasted at least ``settle_after_s`` count too: the scan matcher's local
    map still holds the cut scans' points. Its stream is the verdict per
    scan, as the scan degeneracy check's."""

    name: str
    component: str
    min_no_return: float
    min_edges: int
    min_edge_share: float
    max_ceiling_m: float
    fill_s: float
    hold_s: float
    settle_s: float = 0.0
    settle_after_s: float = 0.0
    reach_share: float = 0.9
    streams: tuple[str, ...] = ("scan_ceiling",)

    def flags(self, geometry: ScanGeometrySeries) -> np.ndarray:
        """True for each scan cut off at a range ceiling short of the
        laser's reach."""
        farthest = np.asarray(geometry.farthest, dtype=float)
        cut = ((np.asarray(geometry.no_return) >= self.min_no_return)
               & (np.asarray(geometry.gap_edges) >= self.min_edges)
               & (np.asarray(geometry.edges_at_ceiling) >= self.min_edge_share)
               & (farthest <= self.max_ceiling_m)
               & (farthest <= self.reach_share * geometry.reach_m))
        t = np.asarray(geometry.t, dtype=float)
        return settled(t, bridged(t, cut, self.fill_s), self.settle_s, self.settle_after_s)

    def deviant(self, values: Mapping[str, np.ndarray]) -> np.ndarray:
        """True where a cut-off scan is at either end of the interval."""
        return np.asarray(values[self.streams[0]]) > 0.0


def bridged(t: np.ndarray, flags: np.ndarray, gap_s: float) -> np.ndarray:
    """``flags`` with every sample between two flagged ones at most ``gap_s``
    apart flagged too."""
    out = flags.copy()
    idx = np.flatnonzero(flags)
    for a, b in zip(idx[:-1], idx[1:]):
        if b > a + 1 and t[b] - t[a] <= gap_s:
            out[a:b] = True
    return out


def settled(t: np.ndarray, flags: np.ndarray, settle_s: float, min_run_s: float = 0.0) -> np.ndarray:
    """``flags`` with every sample less than ``settle_s`` after a run of
    flagged ones that lasted at least ``min_run_s`` flagged too."""
    if settle_s <= 0.0 or not flags.any():
        return flags
    edges = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    first, last = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    out = flags.copy()
    for a, b in zip(first, last):
        if t[b] - t[a] >= min_run_s:
            out |= (t > t[b]) & (t - t[b] < settle_s)
    return out


UnaryCheck = MagnetometerCheck | FieldGyroCheck | GpsQualityCheck | ScanDegeneracyCheck | ScanCeilingCheck


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
    scan = config.scan
    if scan.enabled:
        for axis, (name, component, label) in enumerate(zip(scan.names, scan.components, SCAN_AXES)):
            checks.append(ScanDegeneracyCheck(name, component, axis, scan.min_returns, scan.min_eigenvalue,
                                              scan.min_share, scan.hold_s, (f"scan_degenerate_{label}",)))
    ceiling = config.scan_ceiling
    if ceiling.enabled:
        checks.append(ScanCeilingCheck(ceiling.name, ceiling.component, ceiling.min_no_return, ceiling.min_edges,
                                       ceiling.min_edge_share, ceiling.max_ceiling_m, ceiling.fill_s,
                                       ceiling.hold_s, ceiling.settle_s, ceiling.settle_after_s,
                                       ceiling.reach_share))
    return checks


def scan_streams(checks: list[UnaryCheck], geometry: ScanGeometrySeries | None) -> dict[str, Stream]:
    """The streams of the scan checks among ``checks`` from the front-end's
    ``geometry`` (none without it: the coverage then says the stream is
    absent)."""
    if geometry is None:
        return {}
    t = np.asarray(geometry.t, dtype=float)
    return {c.streams[0]: Stream(t, c.flags(geometry).astype(float))
            for c in checks if isinstance(c, ScanDegeneracyCheck | ScanCeilingCheck)}


def held(t: np.ndarray, deviant: np.ndarray, hold_s: float) -> np.ndarray:
    """True where ``deviant`` has been true on every step for at least ``hold_s``
    (measured from the first step of the run; ``hold_s = 0`` flags at once)."""
    n = len(t)
    idx = np.arange(n)
    starts = deviant & ~np.concatenate(([False], deviant[:-1]))
    run_start = np.maximum.accumulate(np.where(starts, idx, 0)) if n else idx
    return deviant & (t - t[run_start] >= hold_s - _HOLD_EPS_S)
