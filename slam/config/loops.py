"""The ``loops`` section of a pipeline config: loop closing and its checks.

Every key is optional and unknown keys are an error. Distances in metres,
along the path where a key says ``separation`` or ``spacing``.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from validation.base import bounds
from validation.loops.constraint import ObserverConfig
from validation.base.yamlio import Strict


class DescriptorConfig(Strict):
    """Scan Context of a local map (slam.matching.descriptor).

    ``rings`` x ``sectors`` polar cells up to ``max_radius_m``. A keyframe
    further than the geometric search radius is still a candidate when its
    descriptor is within ``max_distance`` (0 = identical, 1 = nothing in
    common) and among the ``candidates`` nearest by ring key. 0 candidates
    turns place recognition off (geometric search only). Such a candidate
    is searched within ``linear_window_m`` of its place and one and a half
    sectors of the descriptor's yaw.
    """

    rings: bounds.Count = Field(20, ge=2)
    sectors: bounds.Count = Field(60, ge=4)
    max_radius_m: bounds.LaserRange_m = Field(15.0, gt=0.0)
    max_distance: float = Field(0.25, ge=0.0, le=1.0)
    candidates: bounds.Count = Field(2, ge=0)
    linear_window_m: bounds.SearchWindow_m = Field(1.5, ge=0.0)


class RegistrationConfig(Strict):
    """Point-to-line ICP (:mod:`slam.matching.icp`).

    ``max_distance_m``: correspondences farther than this are dropped at
    the first iteration; the distance halves each iteration down to
    ``inlier_distance_m``, at which the overlap and residual are judged.
    ``kernel_m``: Cauchy scale of the residuals. A point's normal is fitted
    to the ``normal_half_window`` beams on each side of it in its scan, if
    none of them is more than ``normal_max_gap_m`` from the next;
    ``min_linearity``: map points whose stretch is less straight are not
    matched against (corners, clutter).
    """

    max_distance_m: bounds.MatchDistance_m = Field(0.4, gt=0.0)
    inlier_distance_m: bounds.MatchDistance_m = Field(0.2, gt=0.0)
    kernel_m: bounds.MatchDistance_m = Field(0.1, gt=0.0)
    max_iterations: bounds.Iterations = Field(20, ge=1)
    normal_half_window: bounds.Count = Field(2, ge=1)
    normal_max_gap_m: bounds.LaserRange_m = Field(0.3, gt=0.0)
    min_linearity: float = Field(0.8, ge=0.0, le=1.0)


class CorrelativeConfig(Strict):
    """Coarse search before ICP (:mod:`slam.matching.search`, branch and
    bound), on a likelihood field of ``resolution_m`` cells, in
    ``angular_step_deg`` steps (both coarsened so a window has at most
    11 x 11 translations and 15 yaws), with at most ``max_points`` query
    points (evenly subsampled); of the poses within ``tie_tolerance`` of the
    best score, the one nearest the guess. Skipped when the search window is
    within ``skip_below_m`` and ``skip_below_deg``: ICP's own basin covers it."""

    resolution_m: Annotated[float, bounds.GRID_CELL_M] = Field(0.2, gt=0.0)
    angular_step_deg: Annotated[float, bounds.ANGLE_DEG] = Field(1.0, gt=0.0)
    max_points: bounds.Count = Field(60, ge=3)
    tie_tolerance: float = Field(0.05, ge=0.0, le=1.0)
    skip_below_m: bounds.SearchWindow_m = Field(0.5, ge=0.0)
    skip_below_deg: Annotated[float, bounds.ANGLE_DEG] = Field(5.0, ge=0.0)


class AcceptanceConfig(Strict):
    """When a registration verifies a candidate.

    ``min_overlap``: fraction of query points with a correspondence at the
    end; ``max_rms_m``: RMS point-to-line residual. A direction whose
    information (yaw scaled by the query's median range) is below
    ``min_relative_information`` of the strongest direction's is not pinned
    by the loop (a corridor's axis); a loop with fewer than ``min_pinned``
    directions left (of x, y, yaw) is rejected.
    ``max_correction_m``: the registration may move the query at most this
    far from its guess.
    """

    min_overlap: float = Field(0.6, gt=0.0, le=1.0)
    max_rms_m: bounds.MatchDistance_m = Field(0.05, gt=0.0)
    min_relative_information: float = Field(0.05, ge=0.0, le=1.0)
    min_pinned: bounds.Count = Field(1, ge=1, le=3)
    max_correction_m: bounds.SearchWindow_m = Field(3.0, gt=0.0)


class FileLoopsConfig(Strict):
    """Loops given by the recording (libRSF ``loop t t_other weight``):
    position equality of the two keyframes nearest the stamps, with
    ``sigma_m / sqrt(weight)`` per axis; lines with a weight below
    ``min_weight`` are dropped (libRSF's own threshold is 0.43)."""

    sigma_m: bounds.Sigma_m = Field(0.5, gt=0.0)
    min_weight: Annotated[float, bounds.LOOP_WEIGHT] = Field(0.43, ge=0.0)


class LoopsConfig(Strict):
    """Loop closing (slam.loops) and the loop observer (validation.loops).

    ``source``: ``submaps`` takes the loops the scan-to-submap search found
    (slam.submaps; needs ``submaps.enabled``); ``scans`` detects loops by
    place recognition and geometric search on the laser's local maps and
    verifies them by registration (the keys below); ``file`` takes the
    loops the recording lists (libRSF); ``auto`` uses the file's when the
    recording has any, else the submaps' when they are enabled, else scans.

    Detection walks the keyframes in order, as on the robot. Every
    ``query_spacing_m`` of path, the current keyframe becomes a place and
    looks for earlier places at least ``min_separation_m`` back along the
    path: those within ``candidate_distance_m`` of its estimate, or close by
    descriptor. Around the estimate, the translation is searched within
    ``search_radius_m + search_radius_per_m * (path since the last accepted
    loop)`` (the drift grows with the path; at most ``max_search_radius_m``)
    and the yaw within ``search_yaw_deg + search_yaw_per_m_deg * (the same
    path)``, at most ``max_search_yaw_deg``. Up to ``max_candidates`` are
    verified by registering the query's local map against theirs; a place's
    local map is the scans within ``local_map_m`` of path on each side of
    its keyframe, the query's those within ``query_map_m`` before it (0: its
    own scan only), at most ``local_map_scans`` of them, thinned to
    ``voxel_m``. An accepted loop re-anchors the estimate.

    The registration's information is multiplied by ``information_scale``:
    it treats every point as an independent measurement, which they are not
    (the calibration is in the config that sets it). ``robust_kernel``: the
    loop factors' M-estimator (null: the back-end's). ``gnc``: optimise with
    GTSAM's graduated non-convexity, every factor but the loops a known
    inlier, when loops are present and the optimiser is batch.
    """

    enabled: bool = False
    source: Literal["auto", "submaps", "scans", "file"] = "auto"
    local_map_m: Annotated[float, bounds.PATH_DELTA_M] = Field(3.0, ge=0.0)
    query_map_m: Annotated[float, bounds.PATH_DELTA_M] = Field(3.0, ge=0.0)
    local_map_scans: bounds.Count = Field(10, ge=1)
    voxel_m: Annotated[float, bounds.MAP_VOXEL_M] = Field(0.1, gt=0.0)
    query_spacing_m: Annotated[float, bounds.PATH_DELTA_M] = Field(1.0, ge=0.0)
    min_separation_m: Annotated[float, bounds.PATH_DELTA_M] = Field(10.0, ge=0.0)
    candidate_distance_m: bounds.SearchWindow_m = Field(3.0, ge=0.0)
    search_radius_m: bounds.SearchWindow_m = Field(0.5, ge=0.0)
    search_radius_per_m: Annotated[float, bounds.DRIFT_PER_M] = Field(0.05, ge=0.0)
    max_search_radius_m: bounds.SearchWindow_m = Field(3.0, ge=0.0)
    search_yaw_deg: Annotated[float, bounds.ANGLE_DEG] = Field(3.0, ge=0.0)
    search_yaw_per_m_deg: Annotated[float, bounds.TURN_PER_M_DEG] = Field(0.5, ge=0.0)
    max_search_yaw_deg: Annotated[float, bounds.ANGLE_DEG] = Field(20.0, ge=0.0)
    max_candidates: bounds.Count = Field(2, ge=1)
    information_scale: bounds.InformationScale = Field(1.0, gt=0.0)
    robust_kernel: Literal["none", "huber", "cauchy", "dcs"] | None = None
    robust_param: bounds.RobustParam | None = Field(None, gt=0.0)
    gnc: bool = False
    descriptor: DescriptorConfig = DescriptorConfig()
    correlative: CorrelativeConfig = CorrelativeConfig()
    registration: RegistrationConfig = RegistrationConfig()
    acceptance: AcceptanceConfig = AcceptanceConfig()
    observer: ObserverConfig = ObserverConfig()
    file: FileLoopsConfig = FileLoopsConfig()
