"""Ground-truth motion of a tracked vehicle driving through waypoints.

The path is built from straight lines, circular arcs at gentle corners and
turns on the spot at sharp ones (and wherever the robot pauses). Speed along
each drive is limited by the maximum speed, by the maximum turn rate on arcs
(v <= w_max * R) and by the acceleration limit (a forward and a backward
pass). Spot turns follow a trapezoidal turn-rate profile. The heading is
finally smoothed over ``_SMOOTH_S`` (a track's yaw rate cannot jump) and the
position re-integrated from speed and heading, so the truth is kinematically
consistent: no side slip, dx/dt = v cos(yaw), dy/dt = v sin(yaw).
Everything is deterministic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from slam.errors import GslamError
from validation.base.geometry import wrap_angle
from slam.sim.budget import MAX_MESSAGES
from slam.sim.scenario import RobotConfig

_DS = 0.005  # path sampling for the speed profile, m
_SMOOTH_S = 0.2  # heading smoothing window, s


@dataclass
class Motion:
    """Truth sampled at the truth rate: ``t`` (n,) s from the start, ``x``/``y``
    (n,) m world ENU, ``yaw`` (n,) rad unwrapped, ``v`` (n,) m/s forward
    speed, ``w`` (n,) rad/s yaw rate, ``s`` (n,) m travelled distance."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    v: np.ndarray
    w: np.ndarray
    s: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def xy(self) -> np.ndarray:
        return np.column_stack([self.x, self.y])

    def at(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Linear interpolation of every field at times ``t`` (s)."""
        return {k: np.interp(t, self.t, getattr(self, k)) for k in ("x", "y", "yaw", "v", "w", "s")}


def _spot_turn(angle: float, w_max: float, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Dense (t, w) of a trapezoidal turn by ``angle`` rad."""
    a = abs(angle)
    if a < 1e-9:
        return np.zeros(1), np.zeros(1)
    w_peak = min(w_max, np.sqrt(a * alpha))
    t_acc = w_peak / alpha
    t_const = a / w_peak - t_acc
    total = 2 * t_acc + t_const
    t = np.linspace(0.0, total, max(int(total / 0.001), 3))
    w = np.minimum.reduce([t / t_acc * w_peak, np.full_like(t, w_peak), (total - t) / t_acc * w_peak])
    return t, np.sign(angle) * np.maximum(w, 0.0)


def _drive(
    points: list[np.ndarray], radii: list[float], speeds: list[float], cfg: RobotConfig
) -> dict[str, np.ndarray]:
    """Dense samples (t, v, yaw) of one drive through ``points`` without
    stopping; ``radii[i]`` is the fillet radius at interior point i,
    ``speeds[i]`` the speed limit (m/s) of the leg ending at point i (an arc
    takes the lower of its two legs')."""
    xs, ys, kappa = [np.array([points[0][0]])], [np.array([points[0][1]])], [np.zeros(1)]
    limit = [np.array([speeds[1]])]
    start = points[0]
    for i in range(1, len(points)):
        p, q = points[i], points[i + 1] if i + 1 < len(points) else None
        h_in = np.arctan2(*(p - points[i - 1])[::-1])
        if q is None:
            end, turn, tangent = p, 0.0, 0.0
        else:
            turn = float(wrap_angle(np.arctan2(*(q - p)[::-1]) - h_in))
            tangent = radii[i] * np.tan(abs(turn) / 2)
            end = p - tangent * np.array([np.cos(h_in), np.sin(h_in)])
        n = max(int(np.hypot(*(end - start)) / _DS), 1)
        f = np.arange(1, n + 1) / n
        xs.append(start[0] + f * (end[0] - start[0]))
        ys.append(start[1] + f * (end[1] - start[1]))
        kappa.append(np.zeros(n))
        limit.append(np.full(n, speeds[i]))
        if q is not None and tangent > 0:
            r = radii[i]
            centre = end + r * np.sign(turn) * np.array([-np.sin(h_in), np.cos(h_in)])
            m = max(int(r * abs(turn) / _DS), 1)
            phi = h_in - np.sign(turn) * np.pi / 2 + np.arange(1, m + 1) / m * turn
            xs.append(centre[0] + r * np.cos(phi))
            ys.append(centre[1] + r * np.sin(phi))
            kappa.append(np.full(m, np.sign(turn) / r))
            limit.append(np.full(m, min(speeds[i], speeds[i + 1])))
            start = np.array([xs[-1][-1], ys[-1][-1]])
        else:
            start = end
    x, y, k = np.concatenate(xs), np.concatenate(ys), np.concatenate(kappa)
    v_leg = np.concatenate(limit)
    ds = np.hypot(np.diff(x), np.diff(y))
    w_max = np.radians(cfg.max_turn_rate_deg_s)
    v_lim = np.minimum(v_leg, w_max / np.maximum(np.abs(k), 1e-9))
    v = v_lim.copy()
    v[0] = v[-1] = 0.0
    acc2 = 2.0 * cfg.max_accel_m_s2
    for i in range(1, len(v)):  # forward pass: accelerate no faster than a
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + acc2 * ds[i - 1]))
    for i in range(len(v) - 2, -1, -1):  # backward pass: brake in time
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + acc2 * ds[i]))
    dt = 2.0 * ds / np.maximum(v[1:] + v[:-1], 1e-9)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    yaw = np.unwrap(np.arctan2(np.diff(y), np.diff(x)))
    yaw = np.concatenate([yaw[:1], yaw])
    return {"t": t, "v": v, "yaw": yaw}


def plan_motion(cfg: RobotConfig) -> Motion:
    """Ground truth of the whole run at ``cfg.truth_rate_hz``, starting at
    the first waypoint with yaw ``start_yaw_deg``."""
    waypoints = cfg.path()
    pts = [np.asarray(w[:2], dtype=float) for w in waypoints]
    pauses = [w[2] if len(w) > 2 else 0.0 for w in waypoints]
    speeds = [w[3] if len(w) > 3 else cfg.max_speed_m_s for w in waypoints]
    w_max, alpha = np.radians(cfg.max_turn_rate_deg_s), np.radians(cfg.max_turn_accel_deg_s2)
    spot_limit = np.radians(cfg.spot_turn_above_deg)
    pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (t, v, yaw) each

    def pause(seconds: float, yaw: float) -> None:
        if seconds > 0:
            pieces.append((np.array([0.0, seconds]), np.zeros(2), np.full(2, yaw)))

    def turn(yaw: float, target: float) -> float:
        delta = float(wrap_angle(target - yaw))
        t, w = _spot_turn(delta, w_max, alpha)
        ang = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
        ang *= delta / ang[-1] if abs(ang[-1]) > 1e-12 else 0.0
        pieces.append((t, np.zeros_like(t), yaw + ang))
        return yaw + delta

    yaw = np.radians(cfg.start_yaw_deg)
    pause(cfg.start_pause_s, yaw)
    i = 0
    while i < len(pts) - 1:
        # 1. Collect waypoints up to the next stop (sharp corner, pause or end).
        run, radii = [pts[i]], [0.0]
        j = i + 1
        while True:
            run.append(pts[j])
            if j == len(pts) - 1 or pauses[j] > 0:
                radii.append(0.0)
                break
            h_in = np.arctan2(*(pts[j] - pts[j - 1])[::-1])
            h_out = np.arctan2(*(pts[j + 1] - pts[j])[::-1])
            turn_angle = abs(float(wrap_angle(h_out - h_in)))
            if turn_angle > spot_limit or cfg.corner_radius_m == 0.0:
                radii.append(0.0)
                break
            half = 0.5 * min(np.hypot(*(pts[j] - pts[j - 1])), np.hypot(*(pts[j + 1] - pts[j])))
            radii.append(min(cfg.corner_radius_m, half / max(np.tan(turn_angle / 2), 1e-9)))
            j += 1
        # 2. Turn on the spot towards the first leg, then drive the run.
        heading = float(np.arctan2(*(run[1] - run[0])[::-1]))
        yaw = turn(yaw, heading)
        d = _drive(run, radii, speeds[i : j + 1], cfg)
        d["yaw"] += yaw - d["yaw"][0]
        pieces.append((d["t"], d["v"], d["yaw"]))
        yaw = float(d["yaw"][-1])
        pause(pauses[j], yaw)
        i = j
    pause(cfg.end_pause_s, yaw)
    return _sample(pieces, pts[0], cfg.truth_rate_hz)


def _sample(
    pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray]], start: np.ndarray, rate: float
) -> Motion:
    """Join the pieces, resample at ``rate``, smooth the heading and
    integrate the position."""
    ts, vs, ys, offset = [], [], [], 0.0
    for t, v, yaw in pieces:
        ts.append(t + offset)
        vs.append(v)
        ys.append(yaw)
        offset += float(t[-1]) + 1e-9
    if offset * rate > MAX_MESSAGES:  # the estimate checked before planning missed it
        raise GslamError(f"robot: the planned motion takes {offset / 3600:.1f} h, {offset * rate:.3g} samples "
                         f"of ground truth; at most {MAX_MESSAGES:.0e} (see slam/sim/budget.py)")
    t_all, v_all, y_all = np.concatenate(ts), np.concatenate(vs), np.concatenate(ys)
    dt = 1.0 / rate
    t = np.arange(0.0, offset, dt)
    v = np.interp(t, t_all, v_all)
    yaw = np.interp(t, t_all, y_all)
    half = max(int(round(_SMOOTH_S / dt / 2)), 1)
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    yaw = np.convolve(np.pad(yaw, half, mode="edge"), kernel, mode="valid")
    w = np.gradient(yaw, dt)
    step = 0.5 * (v[1:] + v[:-1]) * dt
    c, s_ = np.cos(yaw), np.sin(yaw)
    x = start[0] + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] * c[1:] + v[:-1] * c[:-1]) * dt)])
    y = start[1] + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] * s_[1:] + v[:-1] * s_[:-1]) * dt)])
    s = np.concatenate([[0.0], np.cumsum(step)])
    return Motion(t=t, x=x, y=y, yaw=yaw, v=v, w=w, s=s)
