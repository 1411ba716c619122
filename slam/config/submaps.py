"""The ``submaps`` section of a pipeline config: scan-to-submap constraints.

Every key is optional and unknown keys are an error. Distances in metres,
angles in degrees, scores in [0, 1] (the mean likelihood-field value at a
scan's points, :mod:`slam.matching.grid`).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from validation.base import bounds
from validation.base.yamlio import Strict as _Strict


class LocalMatchConfig(_Strict):
    """Local SLAM (:mod:`slam.submaps.local`): each scan searched for in the
    submap being built, around the dead-reckoning chain's step.

    The windows are three standard deviations of the chain's step (its
    sources' sigmas and their disagreement), at least ``linear_window_m``
    and ``angular_window_deg``, at most the ``max_`` ones (also where the
    step is unknown). ``min_score``: below it the scan is placed by the
    chain's step alone. ``sigma_xy_m``, ``sigma_yaw_deg``: noise of the
    constraint between a scan and the submap it was matched against.
    """

    linear_window_m: bounds.SearchWindow_m = Field(0.6, ge=0.0)
    angular_window_deg: float = Field(30.0, ge=0.0, le=180.0)
    max_linear_window_m: bounds.SearchWindow_m = Field(1.5, ge=0.0)
    max_angular_window_deg: float = Field(180.0, ge=0.0, le=180.0)
    min_score: float = Field(0.3, ge=0.0, le=1.0)
    sigma_xy_m: bounds.Sigma_m = Field(0.03, gt=0.0)
    sigma_yaw_deg: bounds.Sigma_deg = Field(0.5, gt=0.0)

    @model_validator(mode="after")
    def _windows_ordered(self):
        _windows_ordered(self.linear_window_m, self.max_linear_window_m, "m")
        _windows_ordered(self.angular_window_deg, self.max_angular_window_deg, "deg")
        return self


def _windows_ordered(least: float, most: float, unit: str) -> None:
    key = "linear" if unit == "m" else "angular"
    if least > most:
        raise ValueError(f"{key}_window_{unit} {least:g} {unit} is above max_{key}_window_{unit} {most:g} {unit}: "
                         "a window is at least the one and at most the other")


class RefineConfig(_Strict):
    """Point-to-line ICP after the search (:mod:`slam.matching.icp`), of at
    most ``max_points`` of the scan's points (evenly along its beams).

    Correspondences within ``max_distance_m``, shrinking to
    ``inlier_distance_m``; Cauchy scale ``kernel_m``. A refinement that moves
    more than ``max_shift_m`` or ``max_turn_deg`` from the search's pose, or
    matches fewer than ``min_inliers`` of the scan's points, is not used.
    The refinement's information counts every point as independent; times
    ``information_scale`` it is the match's own uncertainty. A direction
    whose standard deviation exceeds ``max_sigma_m`` (a turn measured by the
    displacement at ``weak_length_m``) is not pinned by the match: the
    constraint gets no information along it.
    """

    max_distance_m: bounds.MatchDistance_m = Field(0.15, gt=0.0)
    inlier_distance_m: bounds.MatchDistance_m = Field(0.1, gt=0.0)
    max_points: bounds.Count = Field(400, ge=10)
    kernel_m: bounds.MatchDistance_m = Field(0.05, gt=0.0)
    max_shift_m: bounds.SearchWindow_m = Field(0.2, gt=0.0)
    max_turn_deg: Annotated[float, bounds.ANGLE_DEG] = Field(3.0, gt=0.0)
    min_inliers: float = Field(0.3, ge=0.0, le=1.0)
    information_scale: bounds.InformationScale = Field(0.1, gt=0.0)
    weak_length_m: bounds.LaserRange_m = Field(5.0, gt=0.0)
    max_sigma_m: bounds.Sigma_m = Field(0.1, gt=0.0)


class ConstraintSearchConfig(_Strict):
    """Scans matched against finished submaps they did not help build
    (:mod:`slam.submaps.graph`).

    Each scan tries at most ``max_per_scan`` submaps whose centre is within
    ``max_distance_m`` of it, nearest first, skipping a submap tied to a
    scan less than ``spacing_m`` of path before. The window around the
    current estimate grows with the path between the scan and the submap:
    ``linear_window_m + linear_window_per_m * path`` up to
    ``max_linear_window_m`` (the same for the angle). A match more than
    ``loop_separation_m`` of path back is a loop (``loop_min_score``), a
    nearer one undoes local drift (``near_min_score``). ``sigma_xy_m``,
    ``sigma_yaw_deg``: their noise, under a Cauchy kernel of
    ``robust_scale`` sigmas. The graph is optimised every
    ``optimise_every`` scans after new constraints; at the end, graduated
    non-convexity drops the constraints it finds outliers, with an inlier
    threshold at the chi-square quantile ``inlier_probability``.
    ``refine_near``: refine a match against its nearest scan of the submap
    and that scan's neighbours. ``agree``: the kinds of constraint (``near``,
    ``loop``) made only when that refinement succeeds within ``agree_m`` and
    ``agree_deg`` of the submap's answer: two maps of the place, one of a
    few metres and one of three scans, must say the same (a submap bent by
    its own drift, or a scan that overlaps the carrier too little, fails).
    ``inside``: a match whose best pose lies on the window's rim makes no
    constraint (the truth may lie beyond it).
    """

    max_distance_m: bounds.SearchWindow_m = Field(10.0, gt=0.0)
    max_per_scan: bounds.Count = Field(3, ge=0)
    spacing_m: Annotated[float, bounds.PATH_DELTA_M] = Field(1.0, ge=0.0)
    loop_separation_m: Annotated[float, bounds.PATH_DELTA_M] = Field(20.0, ge=0.0)
    linear_window_m: bounds.SearchWindow_m = Field(0.3, ge=0.0)
    linear_window_per_m: Annotated[float, bounds.DRIFT_PER_M] = Field(0.02, ge=0.0)
    max_linear_window_m: bounds.SearchWindow_m = Field(3.0, ge=0.0)
    angular_window_deg: float = Field(3.0, ge=0.0, le=180.0)
    angular_window_per_m_deg: Annotated[float, bounds.TURN_PER_M_DEG] = Field(0.2, ge=0.0)
    max_angular_window_deg: float = Field(30.0, ge=0.0, le=180.0)
    near_min_score: float = Field(0.45, ge=0.0, le=1.0)
    loop_min_score: float = Field(0.55, ge=0.0, le=1.0)
    sigma_xy_m: bounds.Sigma_m = Field(0.03, gt=0.0)
    sigma_yaw_deg: bounds.Sigma_deg = Field(0.5, gt=0.0)
    robust_scale: bounds.RobustParam = Field(1.0, gt=0.0)
    inlier_probability: float = Field(0.99, gt=0.0, lt=1.0)
    optimise_every: bounds.Count = Field(10, ge=1)
    refine_near: bool = True
    agree: list[Literal["near", "loop"]] = []
    agree_m: bounds.SearchWindow_m = Field(0.02, gt=0.0)
    agree_deg: Annotated[float, bounds.ANGLE_DEG] = Field(0.3, gt=0.0)
    inside: bool = True

    @model_validator(mode="after")
    def _agree_needs_refine_near(self):
        _windows_ordered(self.linear_window_m, self.max_linear_window_m, "m")
        _windows_ordered(self.angular_window_deg, self.max_angular_window_deg, "deg")
        if self.agree and not self.refine_near:
            raise ValueError(f"agree: {self.agree} compares with the refinement refine_near makes; "
                             "set refine_near: true or agree: []")
        return self


class AmbiguityConfig(_Strict):
    """A scan matched against a finished submap is no constraint when it
    also scores ``ratio`` of its best score or more at a pose more than
    ``exclude_m`` or ``exclude_deg`` away in a direction the match pins:
    repeated structure (doors, racks, pillars at a regular spacing) that the
    match cannot tell apart."""

    enabled: bool = True
    ratio: float = Field(0.9, gt=0.0, le=1.0)
    exclude_m: bounds.SearchWindow_m = Field(0.5, gt=0.0)
    exclude_deg: Annotated[float, bounds.ANGLE_DEG] = Field(5.0, gt=0.0)


class RecognitionConfig(_Strict):
    """Loops found by recognising a place, for drift larger than the
    constraint search's window (:mod:`slam.submaps.graph`): after
    ``min_path_m`` of path without a loop, every ``spacing_m`` the node's
    surroundings (its submap so far) are described by Scan Context
    (``rings`` x ``sectors`` up to ``max_radius_m``) and compared with every
    finished submap at least ``constraints.loop_separation_m`` of path
    back; the ``candidates`` nearest within ``max_distance`` are searched
    for around the pose the descriptor gives, within ``linear_window_m``
    and ``angular_window_deg``, at ``min_score`` or better, unique and
    inside the window. The pose found must lie within the drift the run can
    have gathered since its last loop: the windows plus ``max_drift_per_m``
    and ``max_turn_per_m_deg`` per metre of path; a place further off is a
    look-alike (a symmetric building's other wing). Over the path walked on
    dead reckoning alone (nodes whose scans are too sparse to match, or left
    out by the gating) the run drifts as its odometry does:
    ``blind_drift_per_m`` and ``blind_turn_per_m_deg`` there (None: the
    rates above), until a loop reaches a submap mapped before that path;
    while its drift may exceed ``constraints.linear_window_m``, recognition
    is tried whatever the path since the last loop. A recognition is a loop
    only when a second one, at most ``confirm_within_m`` of path later,
    places the run within ``agree_m`` and ``agree_deg`` of the first; both
    then join the graph without a robust kernel, so the graph closes the
    loop at once."""

    enabled: bool = True
    min_path_m: Annotated[float, bounds.PATH_DELTA_M] = Field(30.0, ge=0.0)
    spacing_m: Annotated[float, bounds.PATH_DELTA_M] = Field(1.0, gt=0.0)
    rings: bounds.Count = Field(20, ge=2)
    sectors: bounds.Count = Field(60, ge=4)
    max_radius_m: bounds.LaserRange_m = Field(20.0, gt=0.0)
    max_distance: float = Field(0.4, gt=0.0, le=1.0)
    candidates: bounds.Count = Field(3, ge=1)
    linear_window_m: bounds.SearchWindow_m = Field(3.0, gt=0.0)
    angular_window_deg: float = Field(12.0, gt=0.0, le=180.0)
    min_score: float = Field(0.6, ge=0.0, le=1.0)
    max_drift_per_m: Annotated[float, bounds.DRIFT_PER_M] = Field(0.1, ge=0.0)
    max_turn_per_m_deg: Annotated[float, bounds.TURN_PER_M_DEG] = Field(1.0, ge=0.0)
    blind_drift_per_m: Annotated[float, bounds.DRIFT_PER_M] | None = Field(None, ge=0.0)
    blind_turn_per_m_deg: Annotated[float, bounds.TURN_PER_M_DEG] | None = Field(None, ge=0.0)
    confirm_within_m: Annotated[float, bounds.PATH_DELTA_M] = Field(5.0, gt=0.0)
    agree_m: bounds.SearchWindow_m = Field(0.3, gt=0.0)
    agree_deg: Annotated[float, bounds.ANGLE_DEG] = Field(3.0, gt=0.0)


class SubmapsConfig(_Strict):
    """Submaps over the keyframes that moved ``node_spacing_m`` or turned
    ``node_turn_deg`` since the last one taken (the nodes; the others keep
    their dead-reckoning steps only). Submaps of ``length_m`` of path (at most ``max_scans`` scans; a new
    one every half of that), anchored at their first scan; scan points
    thinned to ``voxel_m``, scans with fewer than ``min_points`` in range not
    matched; search grids of ``resolution_m`` cells with ``search_depth``
    pooled levels (:mod:`slam.submaps`). Off unless ``enabled``.
    ``blamed_scans``: ``leave_out`` keeps every scan the gating excluded
    (in any direction) out of the submaps: not matched, not inserted, so no
    submap, constraint or loop rests on it; ``keep`` (the default) builds the
    submaps from every scan and gates only the constraints; ``choose`` maps
    both ways where the gating excluded a scan and keeps the map whose
    laser returns land in fewer cells
    (:meth:`slam.pipeline.core.Mapping.map_back_end`)."""

    enabled: bool = False
    node_spacing_m: Annotated[float, bounds.PATH_DELTA_M] = Field(0.25, ge=0.0)
    node_turn_deg: Annotated[float, bounds.ANGLE_DEG] = Field(5.0, ge=0.0)
    length_m: Annotated[float, bounds.PATH_DELTA_M] = Field(4.0, gt=0.0)
    max_scans: bounds.Count = Field(60, ge=2)
    voxel_m: Annotated[float, bounds.MAP_VOXEL_M] = Field(0.05, gt=0.0)
    min_points: bounds.Count = Field(20, ge=3)
    resolution_m: Annotated[float, bounds.GRID_CELL_M] = Field(0.1, gt=0.0)
    search_depth: bounds.Count = Field(6, ge=0, le=10)
    tie_tolerance: Annotated[float, bounds.SCORE] = Field(0.01, ge=0.0)
    blamed_scans: Literal["keep", "leave_out", "choose"] = "keep"
    local: LocalMatchConfig = LocalMatchConfig()
    refine: RefineConfig = RefineConfig()
    constraints: ConstraintSearchConfig = ConstraintSearchConfig()
    ambiguity: AmbiguityConfig = AmbiguityConfig()
    recognition: RecognitionConfig = RecognitionConfig()

    @model_validator(mode="after")
    def _search_grid_size(self) -> "SubmapsConfig":
        # A submap's search grid is padded by twice the widest window on each side (slam.submaps.local).
        pad = 4 * self.max_window_m / self.resolution_m
        if pad > bounds.MAX_SEARCH_PAD_CELLS:
            widest = max((self.local.max_linear_window_m, "local.max_linear_window_m"),
                         (self.constraints.max_linear_window_m, "constraints.max_linear_window_m"),
                         (self.recognition.linear_window_m if self.recognition.enabled else 0.0,
                          "recognition.linear_window_m"))
            raise ValueError(f"{widest[1]} {widest[0]:g} m at resolution_m {self.resolution_m:g} m pads each "
                             f"submap's search grid by {pad:,.0f} cells per axis (at most "
                             f"{bounds.MAX_SEARCH_PAD_CELLS:,}): narrow the window or coarsen the cells")
        return self

    @property
    def max_window_m(self) -> float:
        """The widest linear window any search uses: the submaps' grids are padded by it."""
        windows = [self.local.max_linear_window_m, self.constraints.max_linear_window_m]
        if self.recognition.enabled:
            windows.append(self.recognition.linear_window_m)
        return max(windows)
