"""The maps: the object experience map and its correction, the object map and moving objects."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from neoslam.config.base import Section

__all__ = ["ExperienceMapConfig", "ObjectMapConfig", "MovingObjectsConfig"]


class ExperienceMapConfig(Section):
    """Object experience map and its correction (paper 3.6, eq. 15-18)."""

    gc_distance_threshold: float = Field(
        7.0, gt=0, le=1000, description="max cell-space distance of a loop candidate, bins"
    )
    closure_gate: Literal["grid-cells", "drift", "none"] = Field(
        "drift",
        description="which closures the map accepts: grid-cells, the paper's check (the recognised experience's "
        "cells within gc_distance_threshold of the current); drift, that check widened by gc_drift_cells_per_100m "
        "for the metres of path integration between the current cells and the stored experience's, along the chain "
        "of places recalls anchored them at (the cells drift with the odometry); none, every closure the loop "
        "detector accepted",
    )
    gc_drift_cells_per_100m: float = Field(
        2.0,
        ge=0,
        le=1000,
        description="closure_gate drift: cells added to gc_distance_threshold per 100 m of path integration between "
        "the two cell states, cells "
        "(2: 16 m horizontally and 2 m vertically per 100 m, above the drift of true closures under heavy odometry)",
    )
    similarity_threshold: float = Field(3.0, gt=0, le=1000, description="S_max of eq. 17, cells")
    mu_gc: float = Field(1.0, ge=0, le=1000, description="μ_gc of eq. 17")
    mu_hdc: float = Field(1.0, ge=0, le=1000, description="μ_hdc of eq. 17")
    correction_factor: float = Field(0.5, gt=0, le=1, description="c_f of eq. 18 (NeuroSLAM: 0.5)")
    correction_loops: int = Field(5, ge=0, le=100, description="relaxation passes per frame (NeuroSLAM: 5)")
    backend: Literal["relaxation", "pose-graph"] = Field(
        "pose-graph", description="map correction: the paper's relaxation (eq. 18), or GTSAM pose-graph optimisation"
    )
    odometry_sigma_per_root_metre: float = Field(
        0.05,
        ge=1e-6,
        le=1000,
        description="pose graph: an odometry link's translation std is this times sqrt(metres), m",
    )
    odometry_yaw_sigma_per_root_metre: float = Field(
        0.005, ge=1e-6, le=10, description="pose graph: an odometry link's yaw std is this times sqrt(metres), rad"
    )
    odometry_weights: Literal["distance", "estimated"] = Field(
        "distance",
        description="pose graph: an odometry link's std grows with the metres it spans at the two rates above "
        "(distance), or also with its seconds at the odometry noise the moving-object tracks allow for "
        "(moving_objects.odometry_heading_noise and odometry_distance_noise, raised by their online estimate), "
        "whichever is larger (estimated)",
    )
    odometry_sigma_floor: float = Field(
        0.01, ge=1e-6, le=1000, description="pose graph: least translation std of a link, m"
    )
    loop_sigma: float = Field(0.5, ge=1e-6, le=1000, description="pose graph: std of a loop link's translation, m")
    loop_yaw_sigma: float = Field(0.02, ge=1e-6, le=10, description="pose graph: std of a loop link's yaw, rad")
    robust_kernel: Literal["huber", "cauchy", "none"] = Field("huber", description="pose graph: loop-link kernel")
    robust_threshold: float = Field(3.0, gt=0, le=1000, description="pose graph: kernel scale, in standard deviations")
    withdraw_sigmas: float = Field(
        3.0,
        ge=0,
        le=1000,
        description="pose graph: after each optimisation the loop link the map disagrees with most beyond this many "
        "standard deviations (its whitened residual) is withdrawn and the map solved again without it, until every "
        "loop link agrees: a wrong closure the gate let through is undone (with object landmarks, judged by the pose "
        "graph of odometry and loop links and removed from the landmark solver); 0: never",
    )
    unlocalise_on_withdrawal: Literal["never", "with-landmarks", "always"] = Field(
        "with-landmarks",
        description="whether a withdrawn loop link leaves the robot not localised until the next recognised place "
        "(no experience re-entered by position, no view of an old landmark added): with object landmarks a visit to "
        "the place a wrong closure put the robot at leaves views there in the solver; without them a re-entry adds "
        "nothing to the map, and with odometry noisier than the pose graph's model (simulated heavy) the links "
        "withdrawn are mostly true ones, after which re-entering the map by position keeps the trajectory on it",
    )
    object_landmarks: bool = Field(
        False,
        description="pose graph: the object map's confirmed objects become landmarks (a Point3 each, a bearing-range "
        "factor per (object, experience) observation sum), solved incrementally by iSAM2 (neoslam.mapping.landmarks); "
        "a view of a landmark first seen over localised_distance of travel ago counts only while the robot knows where "
        "it is. False: the pose graph without landmarks, solved at loops",
    )
    landmark_noise: Literal["per-view", "summed"] = Field(
        "per-view",
        description="object landmarks: the noise of an (object, experience) observation sum: per-view, that of one "
        "of its views (views from one experience share the visible surface and the odometry, so their errors do not "
        "average out); summed, the inverse of the summed weight (independent views)",
    )
    landmark_robust_kernel: Literal["huber", "cauchy", "none"] = Field(
        "cauchy",
        description="object landmarks: kernel of the observation factors (Cauchy: a wrong association's weight "
        "falls with the square of its residual, Huber's only linearly)",
    )
    landmark_robust_threshold: float = Field(
        3.0, gt=0, le=1000, description="object landmarks: kernel scale, in standard deviations"
    )
    landmark_centre_sigma: float = Field(
        2.0,
        ge=0,
        le=100,
        description="object landmarks: std of an observation's centre along its ray in the ground plane, beyond the "
        "stereo depth std, in radii of the class's footprint along the ray (keyframes.footprints): the shift from the "
        "visible surface to the middle may be wrong by a radius for every view alike; 0: the shift is taken as exact",
    )
    landmark_height_sigma: float = Field(
        2.0,
        gt=0,
        le=10,
        description="object landmarks: std of an observation's centre in height, m (at least "
        "object_map.position_sigma_floor): heights from stereo boxes are poor and must not pull the map up or down",
    )
    reuse_places: bool = Field(
        True,
        description="lifelong mapping (RatSLAM's rule, beyond the paper): a keyframe that a closure recognises as a "
        "stored one is not stored again and the robot re-enters its experience; while it knows where it is, it "
        "re-enters experiences found at its corrected pose instead of making new ones. False: every keyframe is "
        "stored and makes an experience (the paper), and a street driven every day grows the map every day",
    )
    reuse_radius: float = Field(
        5.0,
        gt=0,
        le=1000,
        description="re-enter an experience this close to the corrected pose, m (keyframes.spacing: the stored "
        "keyframe nearest to a new one on a street driven again is within a spacing)",
    )
    reuse_max_turn_deg: float = Field(
        45.0,
        gt=0,
        le=180,
        description="and only if headed within this of it, degrees: the same street driven the other way is another "
        "experience (another head-direction state), as is a crossing street",
    )
    reentry_distance: float = Field(
        1.5,
        gt=0,
        le=1000,
        description="a closure re-enters the stored keyframe's experience only if it puts the robot within this of "
        "where the map has it (ground plane), m (3 loop_sigma); otherwise the keyframe is stored with a new "
        "experience and a loop link that corrects the map, as the paper does",
    )
    reentry_yaw_deg: float = Field(
        3.0, gt=0, le=180, description="and turned within this of where the map has it, degrees (3 loop_yaw_sigma)"
    )
    localised_distance: float = Field(
        100.0,
        ge=0,
        le=1e6,
        description="the robot knows where it is for this much travel after a recognised place, m (vo odometry "
        "drifts about 1 m in 100 m); 0: re-enter experiences only on a closure",
    )


class ObjectMapConfig(Section):
    """The object map written to objects.csv: observations fused by label and distance."""

    association_radius: float = Field(
        2.5, gt=0, le=1000, description="an observation joins the nearest object this close, m"
    )
    min_observations: int = Field(
        3, gt=0, le=1_000_000, description="objects seen fewer times are left out of objects.csv"
    )
    depth_sigma_at_1m: float = Field(
        0.0015,
        gt=0,
        le=1,
        description="stereo depth std at 1 m, m (keyframes.depth_sigma_at_1m); grows with depth^2: observations are "
        "weighted by their inverse variance, and a far one is associated along its viewing ray within gate_sigmas",
    )
    position_sigma_floor: float = Field(
        0.3,
        ge=0.001,  # a millimetre: far below, a view's information (1/sigma^2) makes the motion fits singular
        le=1000,
        description="no observed centre is known better than this, m (it lies on the visible surface, which changes "
        "with the view): observations nearer than about 14 m weigh alike",
    )
    gate_sigmas: float = Field(
        2.0,
        gt=0,
        le=100,
        description="an observation joins an object within this many depth stds along its viewing ray (at least "
        "association_radius) and association_radius across it: else a far, noisy view of a known object starts a "
        "new one, and a street driven every day collects copies",
    )
    height_tolerance: float = Field(
        6.0,
        gt=0,
        le=1000,
        description="an observation joins an object within this in height, m (at least association_radius; "
        "matching.max_vertical_offset): height and pitch drift move far views up or down by metres, while objects "
        "rarely stand above each other",
    )
    tentative_distance: float = Field(
        60.0,
        gt=0,
        le=1e6,
        description="an object seen fewer than min_observations times is forgotten after this much travel without "
        "another sighting, m (keyframes.window_length): a false detection, or an object glimpsed once a pass, would "
        "otherwise pile up into an object on a street driven every day",
    )


class MovingObjectsConfig(Section):
    """Moving objects kept out of keyframes and the object map (beyond the paper): short tracks of each object's
    observations in the odometry frame (locally accurate), and a weighted fit of position against time; a track
    whose velocity is significant against its uncertainty and fast enough is moving. The depth std of an
    observation is the object map's (object_map.depth_sigma_at_1m, position_sigma_floor)."""

    enabled: bool = Field(
        True,
        description="detect moving objects; their observations join no keyframe and no map object, and objects.csv "
        "lists them with moving = 1 (with traffic it is what keeps loop closure working)",
    )
    gate_radius: float = Field(
        2.5,
        gt=0,
        le=100,
        description="an observation joins the track whose predicted position is this close across the viewing ray, "
        "m (object_map.association_radius)",
    )
    gate_sigmas: float = Field(
        3.0,
        gt=0,
        le=100,
        description="and within this many depth stds along the ray (at least gate_radius): a far stereo centre is "
        "off mostly along the ray",
    )
    significance_sigmas: float = Field(
        5.0,
        gt=0,
        le=100,
        description="a track moves when its fitted velocity is this many stds from zero (Mahalanobis, ground plane): "
        "a static object 40 m away with stereo depth noise stays below it",
    )
    prediction_sigmas: float = Field(
        2.0,
        ge=0,
        le=100,
        description="a track predicts with its fitted velocity shrunk by 1 - (this / its Mahalanobis norm)^2, at "
        "least 0: a static object's noisy velocity moves no prediction, a car's moves it all but",
    )
    hold_sigmas: float = Field(
        3.0,
        ge=0,
        le=100,
        description="a track not judged moving whose velocity is this many stds from zero (and at least min_speed) "
        "is held out of keyframes and the map until it is judged (significance_sigmas or more: never held; 3: "
        "static streets lose no loop recall)",
    )
    min_speed: float = Field(
        2.0,
        ge=0,
        le=100,
        description="and at least this fast, m/s: slower apparent motion is the odometry's local error and the "
        "visible surface changing with the view (a parked car 30 m off seems to move about 1 m/s under heavy "
        "odometry noise); walkers have label_min_speed",
    )
    label_min_speed: dict[str, Annotated[float, Field(ge=0, le=100)]] = Field(
        {"person": 0.7},
        description="min_speed for these labels instead, m/s: a walker (1.0-1.8 m/s) stays below the general "
        "min_speed, is taken as static, and a keyframe holding one does not match the place again",
    )
    judge_after: int = Field(
        3, ge=2, le=1000, description="a track is judged from this many observations on (two fix no velocity)"
    )
    unjudged: Literal["join", "wait", "out"] = Field(
        "wait",
        description="the views of a track not found moving: join, keyframes take them as static; wait, a keyframe "
        "window object is provisional until one of its views belongs to a track known to be static (static_sigmas), "
        "and a provisional object missing where a match puts it is no contradiction (matched, it counts as any "
        "other); out, a track's first judge_after - 1 views are kept out of keyframes and the map",
    )
    static_sigmas: float = Field(
        2.0,
        ge=0,
        le=100,
        description="with unjudged: wait, a track is known to be static once its fitted speed plus this many stds of "
        "its velocity (along the least sure axis) is below min_speed: not only not found moving (a car coming on "
        "from far ahead is neither for its first views)",
    )
    odometry_heading_noise: float = Field(
        0.0032,
        ge=0,
        le=10,
        description="the odometry's heading error as a random walk, rad per square root of a second: a track's "
        "earlier views are turned about the robot by their range times it (the default is the simulated `vo` "
        "profile's 0.01 rad/s yaw-rate noise per 0.1 s frame; `heavy`: 0.032)",
    )
    odometry_distance_noise: float = Field(
        0.063,
        ge=0,
        le=100,
        description="the odometry's position error as a random walk, m per square root of a second (simulated `vo`: "
        "0.2 m/s speed noise per 0.1 s frame; `heavy`: 0.32)",
    )
    odometry_noise: Literal["stated", "estimated"] = Field(
        "estimated",
        description="stated: the tracks allow for odometry_heading_noise and odometry_distance_noise as given; "
        "estimated: those are floors, raised by an online estimate from how the views of slow tracks drift across the "
        "line from the robot over noise_lag frames (mapping/odometry_noise.py)",
    )
    noise_lag: int = Field(
        10,
        ge=2,
        le=10_000,
        description="frames of the estimate's long intervals (1 s at KITTI's 10 Hz): the odometry's error grows with "
        "the interval, the stereo noise does not",
    )
    noise_max_speed: float = Field(
        2.0,
        gt=0,
        le=1000,
        description="tracks whose fitted speed is below this feed the estimate, m/s: parked objects that seem to "
        "move under heavy odometry noise stay in, while traffic is faster",
    )
    noise_window: int = Field(1000, ge=1, le=1_000_000, description="views kept for the estimate (the latest)")
    noise_min_views: int = Field(
        20,
        ge=1,
        le=1_000_000,
        description="views held before the estimate is used (the floors alone until then): parked cars flagged in "
        "those first frames stay flagged, and a drive that loops back to its start misses them",
    )
    noise_bins: int = Field(
        4,
        ge=2,
        le=100,
        description="groups of views by distance from the robot: the heading error moves far objects more, the "
        "position error all alike (a line through the groups' variances separates them)",
    )
    window_scatter: float = Field(
        0.0,
        ge=0,
        le=1e6,
        description="a provisional keyframe-window object (no view of a track known to be static) joins no keyframe "
        "when its views scatter about their best common point by more than this reduced chi-square (their stereo "
        "noise grown by the odometry's error between them, as a track's) within window_span: a car's track that "
        "broke off before it was judged leaves such an object (0, the default: no such test; 3 lifts simulated "
        "recall with traffic, but real detections of parked cars scatter beyond the stereo noise model and the real "
        "KITTI revisit then closes no loop)",
    )
    window_span: float = Field(
        1.2,
        ge=0,
        le=3600,
        description="s: the views of a moving car's window object come within about half a second, a parked car's "
        "provisional object's over a few seconds, where far views' depth noise may scatter them as much",
    )
    track_length: int = Field(
        20, ge=2, le=10_000, description="observations kept per track (the fit's window), a bound on memory"
    )
    max_unseen: float = Field(
        1.5, gt=0, le=3600, description="a track not seen for this long ends, s (detections miss objects for a while)"
    )
    max_speed: float = Field(
        25.0, gt=0, le=1000, description="the fastest an object is taken to move when predicting its track, m/s"
    )
    max_tracks: int = Field(
        256, gt=0, le=1_000_000, description="tracks kept at once (the longest unseen end first), a bound on memory"
    )

    @model_validator(mode="after")
    def _lag_within_a_track(self) -> MovingObjectsConfig:
        if self.noise_lag >= self.track_length:
            raise ValueError(
                f"noise_lag ({self.noise_lag}) must be below track_length ({self.track_length}): the earlier view of "
                "a long interval is one a track still holds"
            )
        return self
