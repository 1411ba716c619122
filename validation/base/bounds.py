"""Physical bounds on configured numbers: what a ground robot's sensors,
maps and clocks can be, so that a value off by many orders of magnitude (a
unit slip, a typo of the exponent) is refused when the config is read, in
one line naming the key, the value and the bound, rather than accepted in
silence and felt later as a hang, a graph GTSAM cannot solve, or a map of
billions of cells.

Each bound is wide: it leaves every shipped config, scenario and the real
recordings of ``../shared/data`` far inside, and says why in words. The
bounds of the recordings' own values (stamps, ranges, rates) live with the
readers (:mod:`slam.readers.data_checks`).
"""

from __future__ import annotations

from typing import Annotated

from pydantic import AfterValidator


def within(lo: float | None, hi: float | None, unit: str, low: str = "", high: str = "") -> AfterValidator:
    """A pydantic validator: the value (None passes) must lie in
    ``[lo, hi]`` (a None end is open); else ``ValueError`` naming the value,
    the bound in ``unit`` and why (``low`` below, ``high`` above)."""

    u = f" {unit}" if unit else ""

    def check(value: float | None) -> float | None:
        if value is None:
            return value
        if lo is not None and value < lo:
            raise ValueError(f"{shown_beside(value, lo)}{u} is below {_exact(lo)}{u}: {low}")
        if hi is not None and value > hi:
            raise ValueError(f"{shown_beside(value, hi)}{u} is above {_exact(hi)}{u}: {high}")
        return value

    check.bounds = (lo, hi)  # for a reader of the schema (tests/test_config_bounds.py asks every number for both)
    return AfterValidator(check)


def shown_beside(value: float, bound: float) -> str:
    """``value`` as ``{:g}`` writes it, or in full where that would read as
    the bound it passes (a value a hair past 100 is not '100 is above 100';
    a whole number one past 2**64 - 1 in all its digits)."""
    short = f"{value:g}"
    if isinstance(value, int) and _exact(bound) != f"{bound:g}":
        return str(value)  # beside a bound in all its digits
    if short != _exact(bound):
        return short
    return str(value) if isinstance(value, int) else repr(float(value))


def _exact(bound: float) -> str:
    """``bound`` as ``{:g}`` writes it, or in all its digits where that
    rounds a whole number (2**64 - 1 is not 1.84467e+19)."""
    short = f"{bound:g}"
    return str(bound) if isinstance(bound, int) and float(short) != bound else short


# --- noise of measurements (sigmas of factors and observers) ---------------

SIGMA_M = within(1e-4, 1e6, "m", "no sensor of a ground robot measures a position to 0.1 mm (and the square of "
                 "a smaller sigma overflows the information)", "a sigma beyond 1000 km says nothing")
"""A position sigma (m)."""
SIGMA_DEG = within(1e-3, 1e4, "deg", "no compass, gyro or scan matcher measures a heading to a thousandth of a "
                   "degree", "a sigma beyond 10,000 deg says nothing a full turn does not")
"""A heading sigma (deg)."""
SIGMA_FLOOR = within(1e-12, 1e6, "(m or rad)", "no sensor resolves 1e-12 m or rad, and the square underflows",
                     "no change would ever be seen")
"""An observer's noise floor, in its streams' unit (m or rad)."""
SIGMA_GROWTH = within(None, 100.0, "", high="a sigma that grows by more than 100 times the motion (per m, per rad, "
                      "per s) says nothing, and its square overflows")
"""How fast a factor's sigma grows with the step (m per m, deg per s, rad per rad)."""
SIGMA_SCALE = within(1e-3, 1e3, "", "a receiver a thousand times better than it says is none (and the square "
                     "of the sigma underflows)", "a fix a thousand times worse than its receiver says is no fix")
"""A multiple of a measured sigma (GPS)."""
INFORMATION_SCALE = within(1e-6, 1e6, "", "the measurement's sigma a thousand times what it measured says nothing "
                           "(and the information underflows)", "a sigma a thousandth of what it measured is no "
                           "measurement's (and the information overflows)")
"""A multiple of a measured information (the inverse square of a sigma scaled
by 1e-3 to 1e3, as :data:`SIGMA_SCALE`)."""
INFLATION = within(None, 1e3, "", high="a sigma a thousand times its own holds the graph together no better, and "
                   "its information underflows")
"""How much a kept factor's sigma is inflated (a multiple, at least 1)."""
ROBUST_PARAM = within(1e-2, 100.0, "sigmas", "every good measurement would be an outlier",
                      "it would down-weight nothing a Gaussian error makes (robust_kernel: none says so)")
"""An M-estimator's parameter, in sigmas of the factor's noise (Huber's and
Cauchy's width, DCS's phi)."""
K_SIGMA = within(0.5, 100.0, "sigmas", "it would flag 62 % of good observations",
                 "it would flag nothing a Gaussian error makes")
"""The multiple of sigma beyond which an observer sees a mismatch."""
MAX_SIGMA_REL = 1000.0
SIGMA_REL = within(None, MAX_SIGMA_REL, "", high="a relative sigma of more than 1000 times the change lets any change pass")
"""A sigma relative to the change observed. ``gslam calibrate`` learns up to
about 30 on streams that do not move together (and then drops them), so
the bound only refuses what no fit gives."""
BOUNDARY = within(None, 1000.0, "(stream units per s)", high="no ground robot turns at 1000 rad/s or "
                  "accelerates at 1000 m/s^2: every trend would be flat")
"""A trend observer's boundary between flat and rising or falling (rad/s, m/s^2)."""
HOLD_S = within(None, 86400.0, "s", high="a deviation held for a day before it counts is never seen")
"""How long a check's deviation must last before it counts (s)."""
SPAN_S = within(None, 86400.0, "s", high="a verdict carried over a day reaches across any run")
"""How far a check carries its verdict: across a gap, after a cut (s)."""
WINDOW_S = within(1e-3, 86400.0, "s", "shorter than any sensor's period: a window of no samples",
                  "a window of over a day reaches across any run")
"""A window or gap a check measures over (s)."""

# --- the Earth's magnetic field --------------------------------------------------

EARTH_FIELD_T = within(1e-6, 1e-3, "T", "twenty times weaker than the Earth's field anywhere (22-67 uT)",
                       "fifteen times the Earth's strongest field")
"""The strength of the Earth's field (T)."""
FIELD_TOLERANCE_T = within(1e-9, 1e-3, "T", "below any magnetometer's noise (about 0.1 uT): every sample would "
                           "deviate", "beyond fifteen times the Earth's strongest field: no deviation would count")
"""How far a field may deviate before a check sees it (T)."""

# --- sizes of maps and keyframes --------------------------------------------

MAP_VOXEL_M = within(1e-3, 100.0, "m", "finer than any laser's range noise", "one point per building")
"""The spacing of a point map (m)."""
GRID_CELL_M = within(5e-3, 10.0, "m", "finer than a 2D laser's range noise (1-3 cm), and a 100 m map of such "
                     "cells holds 4e8 of them", "a cell holds whole rooms")
"""The side of an occupancy or search grid cell (m)."""
KEYFRAME_PERIOD_S = within(1e-4, 3600.0, "s", "faster than any laser or odometry publishes",
                           "a run of an hour would be one keyframe")
"""The time between keyframes (s)."""
KEYFRAME_DISTANCE_M = within(1e-3, 1000.0, "m", "each keyframe would be the last one's noise",
                             "no scan of one keyframe would overlap the next")
"""The travel between keyframes (m)."""
KEYFRAME_YAW_DEG = within(1e-3, 360.0, "deg", "each keyframe would be the last one's noise",
                          "a turn that is never reached")
"""The turn between keyframes (deg)."""

LASER_RANGE_M = within(None, 1000.0, "m", high="beyond any 2D laser's reach")
"""A range of a 2D laser (m): a limit of the scans used, a free-space trace."""
MATCH_DISTANCE_M = within(1e-3, 100.0, "m", "finer than any laser's range noise: no point would find its match",
                          "a point matched that far off is another wall's")
"""A distance within which a scan's point matches the map (m): ICP's
correspondence limits and kernels, KISS-ICP's first threshold."""
RELATIVE_TOLERANCE = within(1e-15, 1.0, "", "below double precision: the optimiser would never stop early",
                            "a relative decrease is at most 1: the optimiser would stop before its first step")
"""An optimiser's relative error decrease that counts as converged."""

SEARCH_WINDOW_M = within(None, 100.0, "m", high="a scan searched for that far from its guess is looked for in "
                         "the whole building, not corrected (and the search grid is padded by the window)")
"""The half-width of a scan matcher's linear search window (m)."""
ANGLE_DEG = within(None, 360.0, "deg", high="beyond a full turn: a turn in the plane is within one")
"""An angle searched, skipped, excluded or agreed within, or turned before a
node (deg)."""
DRIFT_PER_M = within(None, 10.0, "m per m", high="a dead reckoning that drifts ten times the path it travels "
                     "places nothing")
"""How much a position may drift per metre of path (a fraction)."""
TURN_PER_M_DEG = within(None, 360.0, "deg per m", high="a heading that drifts a full turn per metre of path is no "
                        "heading")
"""How much a heading may drift per metre of path (deg per m)."""
SCORE = within(None, 1.0, "", high="a match's score is a mean likelihood in [0, 1]")
"""A share of a match's score, in its own units of [0, 1]."""
LOOP_WEIGHT = within(None, 1e6, "", high="beyond any loop line's weight (slam.readers.librsf refuses more than a "
                     "million): every line would be dropped")
"""A libRSF loop line's weight, which multiplies its information."""

MAX_SEARCH_PAD_CELLS = 2000
"""Most cells a search grid is padded by on each axis (twice its widest
window over its cell size, on both sides): 2000 makes a grid of at least
4e6 cells per pyramid level, a 100 m window at 0.1 m cells."""

# --- times and multiples -----------------------------------------------------

MATCH_OFFSET_S = within(None, 10.0, "s", high="a pose that far from the stamp is another place (a ground robot "
                        "moves metres a second)")
"""The largest time between an estimate's stamp and the pose or fix it is compared with (s)."""
TIME_OFFSET_S = within(-2.0**32, 2.0**32, "s", "no two clocks of one robot differ by more than a ROS time spans "
                       "(136 years)", "no two clocks of one robot differ by more than a ROS time spans (136 years)")
"""A stream's clock offset (s); one as long as the recording is refused
against the recording itself (:mod:`slam.readers.data_checks`)."""
CORRELATION_S = within(1e-3, 1e6, "s", "shorter than any sensor's period: independent errors (null) say so",
                       "an error alike for eleven days is a bias, not a wander")
"""How long a sensor's error stays alike (s)."""
PATH_DELTA_M = within(None, 1e6, "m", high="a path of more than 1000 km is no ground robot's run")
"""A length of path a metric, a check or a search is taken over (m): RPE
deltas, loop separations, submap lengths, spacings along the path."""
ORACLE_K_SIGMA = within(0.5, 100.0, "sigmas", "it would exclude 62 % of good measurements",
                        "it would exclude nothing a Gaussian error makes")
"""The multiple of sigma beyond which the oracle excludes a measurement."""
STREAM_RATE = within(-1000.0, 1000.0, "(stream units per s)", "no ground robot turns at 1000 rad/s, drives at "
                     "1000 m/s or accelerates at 1000 m/s^2", "no ground robot turns at 1000 rad/s, drives at "
                     "1000 m/s or accelerates at 1000 m/s^2")
"""A rate of change of a stream (rad/s, m/s, m/s^2): a relation's offset, how
fast its level may move."""
GAIN = within(-1000.0, 1000.0, "", "one stream changing by a thousand times the other's (or against it) measures "
              "another motion", "one stream changing by a thousand times the other's measures another motion")
"""Stream b's change as a multiple of stream a's, in a residual or offset relation."""
TRAVEL = within(None, 1e6, "(m or rad)", high="a window of more than 1000 km or a million radians of travel "
                "holds a whole run")
"""A length of a stream's travel a relation's window spans (m of path, rad of turn)."""
CUSUM_DRIFT = within(None, 100.0, "sigmas", high="a sum that forgets 100 sigmas a step never grows: no mismatch "
                     "would be seen")
"""How much a CUSUM forgets each step (in sigmas of its residual)."""
MARGIN = within(None, 100.0, "boundaries", high="slopes a hundred boundaries apart would still agree: no turn or "
                "speed of a ground robot is so far from flat")
"""How far two trends' slopes may part (in units of their boundaries)."""
GAP_PERIODS = within(None, 1e4, "periods", high="a stream bridged across ten thousand of its own periods is "
                     "interpolated, not sampled")
"""How many of a stream's sample periods a gap may bridge."""
CLIQUE_STEPS = within(None, 1e9, "steps", high="a search of a billion steps (a microsecond each) runs for "
                      "a quarter of an hour: a budget no run waits out")
"""The work budget of the loop observer's maximum-clique search."""


# --- simulated sensors and the faults added to a recording ---------------------

RATE_HZ = within(1e-3, 1e4, "Hz", "a stream of one message in a quarter of an hour holds nothing a run can use",
                 "faster than any laser, odometry, GPS or IMU publishes (IMUs reach a few kHz)")
"""A sensor's publishing rate (Hz)."""
HEADING_ERROR_DEG = within(1e-2, 180.0, "deg", "below any compass's noise: every sample would be a fault",
                           "a heading is never more than half a turn off: nothing would be a fault")
"""A heading error beyond which a compass is faulty (deg)."""
SLIP_FRACTION = within(1e-3, 10.0, "", "below any odometry's noise: every step would be a fault",
                       "a slipping wheel or track reports a few times its travel: nothing would be a fault")
"""A slip beyond which odometry is faulty, as a fraction of the motion."""
SCAN_MIN_EIGENVALUE = within(None, 1.0, "", high="the smallest of the three eigenvalues of a scan's point-to-line "
                             "information per beam (unit normals, turns over the mean range) stays below 1: every "
                             "scan would be degenerate")
"""The smallest eigenvalue below which a scan's geometry is degenerate."""
DIPOLE_MOMENT_A_M2 = within(None, 1e6, "A m^2", high="ten times a ship's steel hull (about 1e5 A m^2)")
"""A magnetic disturber's moment (A m^2)."""
MULTIPATH_M = within(None, 1000.0, "m", high="a reflected signal biases a fix by metres to a few hundred, "
                     "not a kilometre")
"""A GPS multipath bias (m)."""
AZIMUTH_DEG = within(-360.0, 360.0, "deg", "an azimuth is within a turn", "an azimuth is within a turn")
"""A direction in the plane (deg)."""


Sigma_m = Annotated[float, SIGMA_M]
RobustParam = Annotated[float, ROBUST_PARAM]
InformationScale = Annotated[float, INFORMATION_SCALE]
SearchWindow_m = Annotated[float, SEARCH_WINDOW_M]
Sigma_deg = Annotated[float, SIGMA_DEG]
Rate_hz = Annotated[float, RATE_HZ]
KSigma = Annotated[float, K_SIGMA]
HeadingError_deg = Annotated[float, HEADING_ERROR_DEG]
SlipFraction = Annotated[float, SLIP_FRACTION]
ScanMinEigenvalue = Annotated[float, SCAN_MIN_EIGENVALUE]
DipoleMoment_A_m2 = Annotated[float, DIPOLE_MOMENT_A_M2]
Multipath_m = Annotated[float, MULTIPATH_M]
Azimuth_deg = Annotated[float, AZIMUTH_DEG]
LaserRange_m = Annotated[float, LASER_RANGE_M]
Window_s = Annotated[float, WINDOW_S]
FieldTolerance_T = Annotated[float, FIELD_TOLERANCE_T]
MatchDistance_m = Annotated[float, MATCH_DISTANCE_M]

# --- counts handed to loops and to C++ (KISS-ICP, GTSAM) ----------------------

ITERATIONS = within(1, 100_000, "iterations", high="an optimiser or ICP that has not converged in 100,000 "
                    "iterations will not, and a larger count (1e20) overflows the C++ integer it is passed as")
"""An iteration limit (GTSAM's optimisers, KISS-ICP's and our ICP)."""
THREADS = within(0, 1024, "threads", high="more threads than any machine runs, and a larger count overflows the "
                 "C++ integer it is passed as")
"""A thread count (0: all cores)."""
COUNT = within(None, 1_000_000, "", high="no count of points, candidates, rings, scans or steps a config holds "
               "comes near a million (a typo of the exponent?), and a larger one overflows the C++ integer it is "
               "passed as or sizes an array that fills the memory")
"""Any other count of a config (points per voxel, candidates, rings, scans, steps)."""

Iterations = Annotated[int, ITERATIONS]
Threads = Annotated[int, THREADS]
Count = Annotated[int, COUNT]


# --- simulated runs, sweeps and the times of injected faults -------------------

MAX_MISSION_S = 4 * 3600.0
"""Longest mission simulated (s): 4 h, the 2-hour benchmark run fits twice
(:data:`slam.sim.budget.MAX_DURATION_S`)."""
PAUSE_S = within(None, MAX_MISSION_S, "s", high="a robot standing still that long outlasts the longest mission "
                 "simulated (4 h)")
"""How long a simulated robot waits at a waypoint, at the start or at the end (s)."""
LAPS = within(1, 1000, "laps", "a run drives its route at least once", "a thousand laps within the longest "
              "mission simulated (4 h) leave 14 s a lap, and the route's waypoints are listed once per lap")
"""How often a simulated robot drives its closed route."""
MAX_SEED = 2**64 - 1
SEED = within(0, MAX_SEED, "", "numpy's generators take no negative seed", "64 bits of seed name more runs than "
              "any sweep draws, and truth.json and the job names hold the seed where readers take 64-bit integers")
"""A random seed (of a scenario, of an ablation's seeds and random sweep)."""
SAMPLES = within(1, 1_000_000, "", "a sweep of no point or seed runs nothing", "a million jobs of one input is "
                 "beyond any sweep a machine or cluster runs (gslam ablate refuses more than --max-jobs, 10,000 by "
                 "default)")
"""How many seeds or random samples an ablation draws for one input."""
SWEPT_NUMBER = within(-1e15, 1e15, "", "beyond every bound of a config's or scenario's key (the widest, a clock "
                      "offset's, is 2**32 s), and a wider range overflows the draw",
                      "beyond every bound of a config's or scenario's key (the widest, a clock offset's, is 2**32 s), "
                      "and a wider range overflows the draw")
"""An end of a range an ablation draws a key's values from."""
RECORDING_S = within(0.0, 2.0**32, "s", "a fault's times count from the recording's start",
                     "beyond what a recording spans: its stamps lie within 1970 to 2038 "
                     "(slam.readers.data_checks)")
"""A time within a recording, from its start (s): when an injected fault starts or ends."""
AXIS_COMPONENT = within(-1e6, 1e6, "", "an axis is normalised on load: a component beyond a million says no more "
                        "than one of a few units", "an axis is normalised on load: a component beyond a million says "
                        "no more than one of a few units")
"""A component of a direction normalised on load (a magnetic disturber's moment axis)."""
