"""Configuration: one pydantic model per component, with the paper's values as documented defaults.

Precedence, lowest first: defaults < YAML file (`--config`) < environment variables
`NEOSLAM_<SECTION>__<FIELD>` (for example `NEOSLAM_EXPERIENCE_MAP__CORRECTION_FACTOR=0.3`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from neoslam.errors import ConfigError, InputError
from neoslam.io.text import read_yaml
from neoslam.perception.config import PerceptionConfig

__all__ = [
    "merge_settings",
    "config_values",
    "CameraConfig",
    "WorldConfig",
    "DetectionNoiseConfig",
    "OdometryNoiseConfig",
    "NOISE_PROFILES",
    "SimulatorConfig",
    "GridCellConfig",
    "HeadDirectionConfig",
    "ObjectVectorConfig",
    "HebbianConfig",
    "KeyframeConfig",
    "MatchingConfig",
    "ExperienceMapConfig",
    "ObjectMapConfig",
    "MovingObjectsConfig",
    "EvaluationConfig",
    "MotionLimitsConfig",
    "MapStoreConfig",
    "MAP_SECTIONS",
    "PerceptionConfig",
    "NeoSLAMConfig",
    "load_config",
    "dump_config",
    "describe_validation_error",
    "ENV_PREFIX",
]

ENV_PREFIX = "NEOSLAM_"
ENV_NESTED_DELIMITER = "__"


class _Section(BaseModel):
    # allow_inf_nan=False: .inf or .nan in a YAML file or a NEOSLAM_* variable is refused with the field's name
    # (an infinite spacing or cell size validates as "> 0" and then breaks a run far from its cause).
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class CameraConfig(_Section):
    """Rectified stereo camera; defaults are KITTI odometry sequences 04-12 (left grey camera)."""

    fx: float = Field(707.0912, gt=0, le=1e5, description="focal length, px")
    fy: float = Field(707.0912, gt=0, le=1e5, description="focal length, px")
    cx: float = Field(601.8873, ge=-1e5, le=1e5, description="principal point x, px")
    cy: float = Field(183.1104, ge=-1e5, le=1e5, description="principal point y, px")
    width: int = Field(1226, gt=0, le=100_000, description="image width, px")
    height: int = Field(370, gt=0, le=100_000, description="image height, px")
    baseline: float = Field(0.5372, gt=0, le=100, description="stereo baseline, m (379.8145 / fx)")
    height_above_ground: float = Field(1.65, gt=0, le=100, description="camera height above the road, m (KITTI)")
    max_range: float = Field(40.0, gt=0, le=1e4, description="detections beyond this depth are not reported, m")
    min_range: float = Field(1.0, gt=0, le=1e4, description="closer objects fill the view and are not reported, m")


class WorldConfig(_Section):
    """Objects placed along a route the way a street holds them; a share of them may move (traffic)."""

    spacing: float = Field(
        7.0, ge=0.5, le=1000, description="mean gap between candidate object slots along the road, m"
    )
    occupancy: float = Field(0.55, ge=0, le=1, description="share of slots (each side) that hold an object")
    lateral_offset: float = Field(5.0, gt=0, le=1000, description="distance of parked objects from the route centre, m")
    lateral_jitter: float = Field(0.6, ge=0, le=100, description="std of the lateral placement, m")
    min_separation: float = Field(3.0, ge=0.1, le=1000, description="no two objects closer than this, m")
    road_clearance: float = Field(
        3.0, gt=0, le=1000, description="no object centre is placed closer than this to any part of the route, m"
    )
    revisit_radius: float = Field(
        8.0, gt=0, le=1000, description="route points this close to an earlier pass place nothing"
    )
    class_mix: dict[str, float] = Field(
        default_factory=lambda: {"car": 0.70, "truck": 0.08, "bicycle": 0.10, "person": 0.12},
        description="relative frequency of each class",
    )
    moving_fraction: float = Field(
        0.0,
        ge=0,
        le=1,
        description="share of the placed objects that move (0: a static street): cars, trucks and bicycles drive "
        "along the route in a lane, both ways, people walk along their kerb; all turn round at the route's ends",
    )
    lane_offset: float = Field(
        1.8, gt=0, le=20, description="distance of a moving vehicle's lane from the route's centre line, m"
    )
    drive_on: Literal["right", "left"] = Field(
        "right", description="side of the road moving vehicles keep to, seen in their direction of travel"
    )
    vehicle_speed: tuple[float, float] = Field(
        (5.0, 12.0), description="(slowest, fastest) speed of moving cars and trucks, m/s, drawn uniformly"
    )
    bicycle_speed: tuple[float, float] = Field(
        (3.0, 6.0), description="(slowest, fastest) speed of moving bicycles, m/s, drawn uniformly"
    )
    walking_speed: tuple[float, float] = Field(
        (1.0, 1.8), description="(slowest, fastest) speed of walking people, m/s, drawn uniformly"
    )
    turn_length: float = Field(
        10.0, gt=0, le=1000, description="a vehicle turning round at an end of the route changes lanes over this, m"
    )
    rows: tuple[tuple[float, float, float], ...] | None = Field(
        None,
        description="rows of objects instead of both sides at lateral_offset with occupancy and lateral_jitter: "
        "(signed lateral offset from the route, m, left positive; objects per 100 m of route; std of the lateral "
        "placement, m), each a line of slots every `spacing` metres",
    )

    @model_validator(mode="after")
    def _rows_fit_the_slots(self) -> WorldConfig:
        for offset, density, jitter in self.rows or ():
            if not 0 < abs(offset) <= 1000 or not 0 <= jitter <= 100 or not 0 <= density * self.spacing / 100.0 <= 1:
                raise ValueError(
                    f"row ({offset}, {density}, {jitter}): needs a non-zero offset up to 1000 m, 0 to "
                    f"{100.0 / self.spacing:.3g} objects per 100 m (one slot every spacing = {self.spacing} m) and a "
                    "jitter of 0 to 100 m"
                )
        return self

    @field_validator("vehicle_speed", "bicycle_speed", "walking_speed")
    @classmethod
    def _speed_range(cls, speeds: tuple[float, float]) -> tuple[float, float]:
        if not 0 < speeds[0] <= speeds[1] <= 100:
            raise ValueError(f"needs 0 < slowest <= fastest <= 100 m/s, got {speeds}")
        return speeds

    @field_validator("class_mix")
    @classmethod
    def _mix_of_classes(cls, mix: dict[str, float]) -> dict[str, float]:
        if not mix or any(not label.strip() or share < 0 for label, share in mix.items()) or sum(mix.values()) <= 0:
            raise ValueError(f"needs class names with shares >= 0 that add up to more than 0, got {mix}")
        return mix


def _check_table(table: tuple[tuple[float, float], ...] | None, upper: float | None) -> None:
    """A (key, value) table to interpolate: keys strictly increasing, values in [0, upper]."""
    if table is None:
        return
    keys = [key for key, _ in table]
    if not table or any(b <= a for a, b in zip(keys, keys[1:], strict=False)):
        raise ValueError("needs at least one (key, value) pair, keys strictly increasing")
    if any(value < 0 or (upper is not None and value > upper) for _, value in table):
        raise ValueError(f"values must lie in [0, {upper}]")


class DetectionNoiseConfig(_Section):
    """What YOLO plus ORB stereo matching get wrong."""

    miss_rate: float = Field(0.1, ge=0, le=1, description="probability to miss a visible object, at zero range")
    miss_rate_at_max_range: float = Field(0.4, ge=0, le=1, description="miss probability at max_range")
    label_confusion: float = Field(0.02, ge=0, le=1, description="probability to report another class")
    false_positives_per_frame: float = Field(0.2, ge=0, le=100, description="Poisson mean of spurious detections")
    pixel_sigma: float = Field(1.0, ge=0, le=1000, description="std of the detected centre in the image, px")
    disparity_sigma: float = Field(
        0.3, ge=0, le=1000, description="std of the object disparity, px (depth error ~ z^2)"
    )
    surface_bias: float = Field(
        1.0, ge=0, le=1, description="share of the half-extent by which the stereo centre sits on the near surface"
    )
    box_sigma: float = Field(2.0, ge=0, le=1000, description="std of each box edge, px")
    patch_size: int = Field(16, gt=1, le=256, description="side of the grey appearance patch, px")
    patch_noise: float = Field(10.0, ge=0, le=1000, description="std of per-observation patch noise, grey levels")
    patch_gain_sigma: float = Field(0.08, ge=0, le=10, description="std of the per-observation brightness gain")
    texture_individuality: float = Field(
        0.5, ge=0, le=1, description="0: all objects of a class look alike, 1: every object looks unique"
    )
    detection_probability: tuple[tuple[float, float], ...] | None = Field(
        None,
        description="(depth, m; probability that a visible object is detected and placed) points, interpolated "
        "linearly and held beyond the ends; None: 1 - the linear miss_rate model",
    )
    column_factor: tuple[tuple[float, float], ...] | None = Field(
        None,
        description="(offset of the object's image column from the principal point, as a share of the half image "
        "width: 0 on the axis, 1 at the edge; factor on detection_probability) points, interpolated; None: 1",
    )
    border_margin: float | None = Field(
        None,
        ge=0,
        le=1e4,
        description="an object whose box comes this close to the image border (or reaches behind the camera) is cut "
        "off and not placed, px, as the real stereo step does (perception.stereo.border_margin); None: placed",
    )
    occlusion_cover: float | None = Field(
        None,
        gt=0,
        le=1,
        description="an object whose box is covered by at least this share by nearer objects' boxes is hidden; "
        "None: no occlusion",
    )
    max_range: float | None = Field(
        None,
        gt=0,
        le=1e4,
        description="objects farther than this are not reported, m (the real stereo step: "
        "perception.stereo.max_depth); None: camera.max_range",
    )
    false_positive_depth: tuple[float, float] | None = Field(
        None, description="depth range of false positives, m; None: 3 x camera.min_range to camera.max_range"
    )

    @field_validator("detection_probability", "column_factor")
    @classmethod
    def _tables(cls, table, info):
        _check_table(table, 1.0 if info.field_name == "detection_probability" else None)
        return table

    @field_validator("false_positive_depth")
    @classmethod
    def _depth_range(cls, depths):
        if depths is not None and not 0 < depths[0] <= depths[1] <= 1e4:
            raise ValueError("needs 0 < near <= far <= 10000 m")
        return depths


class OdometryNoiseConfig(_Section):
    """Noise of the visual odometry, applied to the true per-frame motion."""

    sigma_speed: float = Field(0.2, ge=0, le=100, description="std of the forward speed, m/s, per frame")
    sigma_yaw_rate: float = Field(0.01, ge=0, le=10, description="std of the yaw rate, rad/s, per frame")
    speed_scale_bias: float = Field(0.01, ge=-1, le=10, description="relative speed error, +0.01 = 1 % too long")
    yaw_rate_bias: float = Field(0.001, ge=-10, le=10, description="constant yaw-rate error, rad/s")
    sigma_vertical_speed: float = Field(0.02, ge=0, le=100, description="std of the vertical speed, m/s")
    sigma_pitch_rate: float = Field(0.002, ge=0, le=10, description="std of the pitch rate, rad/s")


NOISE_PROFILES: dict[str, OdometryNoiseConfig] = {
    "none": OdometryNoiseConfig(
        sigma_speed=0.0,
        sigma_yaw_rate=0.0,
        speed_scale_bias=0.0,
        yaw_rate_bias=0.0,
        sigma_vertical_speed=0.0,
        sigma_pitch_rate=0.0,
    ),
    "vo": OdometryNoiseConfig(),
    "heavy": OdometryNoiseConfig(sigma_speed=1.0, sigma_yaw_rate=0.1, sigma_vertical_speed=0.1, sigma_pitch_rate=0.01),
    # The upper ends of the paper's noise (section 4.3: 0..1 m/s and 0..0.5 rad/s).
    "paper-max": OdometryNoiseConfig(
        sigma_speed=1.0, sigma_yaw_rate=0.5, sigma_vertical_speed=0.1, sigma_pitch_rate=0.01
    ),
}


class SimulatorConfig(_Section):
    """`neoslam simulate`: world, camera, detection and odometry noise."""

    seed: int = Field(0, ge=0, le=2**63 - 1, description="seed of every random draw of a simulation")
    camera: CameraConfig = CameraConfig()
    world: WorldConfig = WorldConfig()
    detection: DetectionNoiseConfig = DetectionNoiseConfig()
    detection_profile: str = Field(
        "real",
        description="named detection model and street (see neoslam.sim.profiles: real, calibrated to the real front "
        "end on KITTI 06; ideal, the simulator's own defaults, a richer street and detector): it fills `detection` "
        "and `world`, and the fields given there override it",
    )
    noise_profile: str = Field("vo", description="name of the odometry noise profile (see NOISE_PROFILES)")
    odometry: OdometryNoiseConfig = OdometryNoiseConfig()
    frame_period: float = Field(
        0.1037, ge=0.001, le=10, description="s between frames when no times are given (KITTI mean)"
    )

    @model_validator(mode="before")
    @classmethod
    def _apply_detection_profile(cls, data: Any) -> Any:
        from neoslam.sim.profiles import with_detection_profile  # the profiles are built from this module's models

        return with_detection_profile(data) if isinstance(data, dict) else data


# Cells along one grid-cell axis: fewer than 4 leave no room for a packet (below 3 the activity dies at once);
# 128^3 cells already cost ~50 ms a frame.
GridAxis = Annotated[int, Field(ge=4, le=128)]


def _odd_extent(size: int) -> int:
    """A kernel extent must be odd: an even one has no centre cell and biases the packet by half a cell."""
    if size % 2 == 0:
        raise ValueError(f"must be odd (a centre cell and as many cells each side), got {size}")
    return size


class GridCellConfig(_Section):
    """3-D grid-cell continuous attractor network (paper 3.3, eq. 6; NeuroSLAM defaults)."""

    dims: tuple[GridAxis, GridAxis, GridAxis] = Field((36, 36, 36), description="cells along x, y, z (all cyclic)")
    excitation_size: int = Field(7, gt=0, le=99, description="excitatory kernel extent, cells")
    excitation_sigma: float = Field(1.5, ge=0.01, le=100, description="δx = δy = δz of eq. 6, cells")
    inhibition_size: int = Field(5, gt=0, le=99, description="inhibitory kernel extent, cells")
    inhibition_sigma: float = Field(2.0, ge=0.01, le=100, description="inhibitory kernel σ, cells")
    global_inhibition: float = Field(2e-4, ge=0, le=1, description="subtracted from every cell each step")
    injection_energy: float = Field(0.1, ge=0, le=10, description="energy added at a recalled cell state")
    packet_size: int = Field(4, ge=0, le=64, description="decode window = peak ± packet_size cells")
    metres_per_cell: float = Field(
        8.0,
        ge=0.01,
        le=1000,
        description="horizontal metres of motion per cell: the paper's 7-bin check of loop candidates then admits "
        "56 m of odometry drift (2 m per cell rejected most true closures of KITTI 00 and 02, see kitti_sim.py)",
    )
    metres_per_cell_vertical: float = Field(1.0, ge=0.01, le=1000, description="vertical metres of motion per cell")
    shift_kernel: Literal["zero-skew", "linear"] = Field(
        "zero-skew",
        description="sub-cell path-integration shift: 3-tap zero-skew blend, or NeuroSLAM's 2-tap linear one "
        "(under-integrates slow motion by up to 10 %)",
    )
    settle_in_packet_frame: bool = Field(
        True, description="settle with the packet moved onto its nearest cell: no lattice pinning (NeuroSLAM: no)"
    )
    dtype: Literal["float32", "float64"] = Field("float32", description="activity precision (float32: faster)")

    _odd_kernels = field_validator("excitation_size", "inhibition_size")(_odd_extent)


class HeadDirectionConfig(_Section):
    """1-D ring of head-direction cells for yaw (paper 3.3: 36 cells)."""

    cells: int = Field(36, ge=4, le=3600, description="cells around the ring (10 degrees each)")
    excitation_size: int = Field(7, gt=0, le=99, description="excitatory kernel extent, cells")
    excitation_sigma: float = Field(1.9, ge=0.01, le=100, description="excitatory σ, cells (NeuroSLAM)")
    inhibition_size: int = Field(5, gt=0, le=99, description="inhibitory kernel extent, cells")
    inhibition_sigma: float = Field(3.0, ge=0.01, le=100, description="inhibitory σ, cells (NeuroSLAM)")
    global_inhibition: float = Field(2e-4, ge=0, le=1, description="subtracted from every cell each step")
    injection_energy: float = Field(0.1, ge=0, le=10, description="energy added at a recalled cell state")
    packet_size: int = Field(5, ge=0, le=1800, description="decode window = peak ± packet_size cells")
    shift_kernel: Literal["zero-skew", "linear"] = Field(
        "zero-skew",
        description="sub-cell path-integration shift: 3-tap zero-skew blend, or NeuroSLAM's 2-tap linear one",
    )
    settle_in_packet_frame: bool = Field(
        True, description="settle with the packet moved onto its nearest cell: no lattice pinning (NeuroSLAM: no)"
    )
    dtype: Literal["float32", "float64"] = Field("float32", description="activity precision (float32: faster)")

    _odd_kernels = field_validator("excitation_size", "inhibition_size")(_odd_extent)


class ObjectVectorConfig(_Section):
    """Object-vector cells network (paper 3.4, eq. 7-13)."""

    peak_rate: float = Field(1.2, ge=-1000, le=1000, description="a of eq. 7, Hz")
    baseline_rate: float = Field(0.0, ge=-1000, le=1000, description="b of eq. 7, Hz")
    field_sigma: float = Field(5.0, ge=0.01, le=1e4, description="σ of eq. 10 along the preferred direction, m")
    field_sigma_across: float | None = Field(
        None,
        ge=0.01,
        le=1e4,
        description="σ across the preferred direction, m (elliptical field); None: equal, as eq. 10",
    )
    preferred_distance: float = Field(10.0, ge=0, le=1e4, description="distance of the field's centre, m")
    preferred_direction: float = Field(
        0.0, ge=-10, le=10, description="allocentric direction of the field's centre, rad (φ, eq. 9)"
    )
    distance_scale: float = Field(
        10.0,
        ge=0.01,
        le=1e4,
        description="inputs d are divided by this, m: about 2σ, so the field spans as much of d as of φ",
    )
    direction_encoding: Literal["cos_sin", "raw"] = Field(
        "cos_sin", description="φ as (cos φ, sin φ), continuous across ±π (fits better), or raw radians / π"
    )
    hidden_units: int = Field(32, gt=0, le=4096, description="N hidden ELU units (eq. 12)")
    optimizer: Literal["adam", "sgd"] = Field("adam", description="plain SGD at lr 0.001 hardly learns in 10 epochs")
    learning_rate: float = Field(0.001, gt=0, le=10, description="paper: 0.001")
    batch_size: int = Field(
        1, gt=0, le=100_000, description="object vectors per update; 1: one per observation, as eq. 13"
    )
    epochs: int = Field(10, gt=0, le=1000, description="paper: 10")
    keyframes_per_epoch: int = Field(20, gt=0, le=100_000, description="paper: 20")
    seed: int = Field(0, ge=0, le=2**63 - 1, description="weight initialisation and shuffling seed")


class HebbianConfig(_Section):
    """Keyframe-to-cell associations (eq. 14)."""

    learning_rate: float = Field(1.0, gt=0, le=1e6, description="τ of eq. 14")
    sparsity: float = Field(0.1, gt=0, le=1, description="store only cells above this fraction of the peak")
    recall_gain: float = Field(
        20.0,
        ge=0,
        description="a recall injects this many times the cells' injection_energy (NeuroSLAM's energy per frame of "
        "a re-seen view; a closure is a place verified over consecutive keyframes): 2.0 of a packet of 1 by "
        "default, so a recall re-anchors the cells (at 0.1 it moved them 9 % of a 1-cell offset, none of 5 cells)",
    )
    recall_on: Literal["detected", "accepted"] = Field(
        "accepted",
        description="which closures recall their place: only those the experience map's closure gate accepted (the "
        "paper's order; the default: with closure_gate drift it meets the heavy-drift targets, and a "
        "false closure the detector accepts cannot re-anchor the cells and so open the gate for the next one: on the "
        "town trap, 5 false closures with detected, none with accepted, benchmarks/gating.py), or every one the "
        "detector accepts (NeuroSLAM's local-view calibration: the gate then compares re-anchored cells; with the "
        "paper's grid-cell check this is what keeps true closures after heavy drift)",
    )


class KeyframeConfig(_Section):
    """Object keyframes (paper 3.2): the current object and the objects around it, in the world frame.

    Observations are first fused over a short stretch of road (the local window), where odometry drift is small,
    so that a keyframe's object centres average many stereo measurements.
    """

    e_max: float = Field(1.5, gt=0, le=1000, description="e_max of eq. 2, m (paper)")
    neighbourhood_radius: float = Field(
        30.0, gt=0, le=1000, description="objects this close to the current object join its keyframe, m (paper: e_max)"
    )
    sparse_objects: int = Field(
        5,
        gt=0,
        le=1000,
        description="where fewer objects stand within neighbourhood_radius (a sparse street: real KITTI streets "
        "through a real detector), the neighbourhood grows until it holds this many (5: measured against 6, 8 and "
        "no growth on the real revisit and on simulated drives, benchmarks/loops.py --config)",
    )
    sparse_neighbourhood_radius: float = Field(
        60.0, gt=0, le=1000, description="the largest the neighbourhood grows to on a sparse street, m"
    )
    spacing: float = Field(5.0, ge=0.01, le=1e4, description="a keyframe every this many metres of travel")
    min_objects: int = Field(4, gt=0, le=1000, description="fewer objects in the neighbourhood make no keyframe")
    window_length: float = Field(60.0, gt=0, le=1e4, description="observations fused over this much recent travel, m")
    association_radius: float = Field(
        2.5, gt=0, le=1000, description="an observation joins a window object this close, m"
    )
    min_observations: int = Field(3, gt=0, le=1_000_000, description="window objects seen fewer times are left out")
    footprints: dict[str, tuple[float, float]] = Field(
        default_factory=lambda: {"car": (4.3, 1.8), "truck": (8.0, 2.5), "bicycle": (1.8, 0.6), "person": (0.6, 0.6)},
        description="typical length and width of each class, m, lying along the road: stereo points lie on the "
        "visible surface, and the centre is half the footprint further along the viewing ray",
    )
    depth_sigma_at_1m: float = Field(
        0.0007,
        gt=0,
        le=1,
        description="stereo depth std at 1 m, m; grows with depth^2, weights the fusion and gives the keyframe "
        "objects' covariances (0.27 px of disparity at KITTI's focal length x baseline, 380 px m: the real front "
        "end's 0.23 px, benchmarks/calibrate_sim.py, with room for its heavier tails)",
    )
    bearing_sigma: float = Field(
        0.002,
        gt=0,
        le=1,
        description="std of a view's bearing to an object's centre, rad (about 1.5 px at KITTI's focal length): with "
        "the depth std it gives each keyframe object's covariance, which the matching's tolerances follow",
    )

    @field_validator("footprints")
    @classmethod
    def _footprints_in_metres(cls, footprints: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
        for label, (length, width) in footprints.items():
            if not (0 <= length <= 100 and 0 <= width <= 100):
                raise ValueError(f"{label}: length and width must lie in [0, 100] m, got ({length}, {width})")
        return footprints


TRIANGLE_SIDE_BITS = 8  # loop.triangles packs each side's bin into this many bits of a key


class MatchingConfig(_Section):
    """Keyframe matching and verification (eq. 2-5)."""

    appearance_rmse_threshold: float = Field(80.0, gt=0, le=1000, description="max patch RMSE, 0-255 grey (paper)")
    score_threshold: float = Field(
        1.0, ge=0, le=1e6, description="a score above this is a loop-closure candidate (paper)"
    )
    min_support: int = Field(2, ge=0, le=1000, description="a match needs this many other matches with consistent e_ij")
    min_inliers: int = Field(4, gt=0, le=1000, description="verified matched objects needed to accept a closure")
    min_inlier_ratio: float = Field(
        0.5, ge=0, le=1, description="and this share of the smaller keyframe's objects (a place, not a pattern)"
    )
    tolerances: Literal["covariance", "fixed"] = Field(
        "covariance",
        description="how far a matched object may lie from where the fit puts it: covariance, by each centre's "
        "covariance from its views (a chi-square gate; far objects are allowed their depth noise, near ones stay "
        "strict; loop.verification); fixed, within inlier_distance and max_fit_residual whatever the distance",
    )
    centre_sigma: float = Field(
        0.25,
        gt=0,
        le=100,
        description="std of a keyframe object's centre that no number of views lowers, m, added to its covariance "
        "in each ground axis: the footprint model that moves a view from the visible surface to the middle, the "
        "odometry's drift within the keyframe's window",
    )
    affinity_sigmas: float = Field(
        2.5,
        gt=0,
        le=100,
        description="with tolerances covariance: the tolerance of eq. 2 widens from e_max to this many stds of "
        "|e_ij - e_i'j'| where the centres' covariances make that larger",
    )
    inlier_probability: float = Field(
        0.99,
        gt=0,
        lt=1,
        description="with tolerances covariance: a matched pair is an inlier of the fit within the chi-square "
        "gate (2 degrees of freedom) that holds a right pair with this probability",
    )
    fit_probability: float = Field(
        0.999,
        gt=0,
        lt=1,
        description="with tolerances covariance: the fit's sum of squared normalised residuals must stay within the "
        "chi-square bound (2k - 3 degrees of freedom) that holds a right fit with this probability",
    )
    max_inlier_distance: float = Field(
        4.0,
        gt=0,
        le=1000,
        description="with tolerances covariance: no matched pair further apart than this under the fit is an "
        "inlier, whatever its covariance, m",
    )
    object_area: float = Field(
        150.0,
        gt=0,
        le=1e6,
        description="with tolerances covariance: street area per object, m² (a parked object every 12 m of a "
        "12 m band): with the label's share, the density of strangers that could fall in a pair's gate by chance",
    )
    contradiction_bits: float = Field(
        4.0, ge=0, le=1000, description="with tolerances covariance: evidence a contradicted object costs, bits"
    )
    min_evidence_bits: float = Field(
        6.0,
        ge=0,
        le=1e4,
        description="with tolerances covariance: a verified match carries at least this much evidence that the two "
        "keyframes show one place, bits (loop.verification)",
    )
    max_fit_residual: float = Field(
        0.6, gt=0, le=1000, description="with tolerances fixed: max RMS residual of the rigid fit, m (ground plane)"
    )
    inlier_distance: float = Field(
        1.2,
        gt=0,
        le=1000,
        description="with tolerances fixed: a match fits the rigid transform within this, m; others are left out of "
        "the fit and its RMS (about 3 σ of a right match seen from the other direction, where a truck's or a "
        "cross-street object's centre is off by a metre)",
    )
    max_contradictions: int = Field(
        4,
        ge=0,
        le=10_000,
        description="reject if under the fit more objects than this stand well inside the other keyframe's ground "
        "with no object of their label near them there: a place driven again shows the same objects, a street that "
        "only shares part of its layout shows others (closures accepted without this check, benchmarks/loops.py, "
        "vo, seeds 1-10: 87 % of the true ones have none and 98.7 % at most 2; the false ones 2 to 7)",
    )
    contradiction_radius: float = Field(
        2.5,
        gt=0,
        le=1000,
        description="an object with one of its label this close under the fit is not contradicted, m "
        "(keyframes.association_radius: observations this close are one object; a right match seen from the other "
        "side or a truck's centre can be off by more than the inlier distance)",
    )
    contradiction_margin: float = Field(
        3.0,
        ge=0,
        le=1000,
        description="only objects this far inside the other keyframe's ground count, m: near its edge an object may "
        "fall in one keyframe and not in the other by the noise of its centre",
    )
    max_place_offset: float = Field(
        3.5,
        gt=0,
        le=1000,
        description="accept only if the fit puts the two robot poses this close, m: the same place is within 5 m "
        "(evaluation.loop_max_distance), less the error of the fit's offset, up to 0.6 m with vo odometry and "
        "1.5 m with heavy (simulated KITTI drives)",
    )
    max_vertical_offset: float = Field(
        6.0,
        gt=0,
        le=1000,
        description="reject if the fit puts the two robot poses this far apart in height, m: a bridge "
        "over a street is another place (KITTI 02 and 08 ground truth disagree by up to 5.8 m at one place)",
    )
    max_yaw_drift_deg: float = Field(
        30.0,
        gt=0,
        le=360,
        description="reject a fit that turns the query's world by more than this, degrees, plus yaw_drift_per_100m: "
        "its rotation is the odometry's heading drift between the two passes; a layout that is nearly point-"
        "symmetric can also fit turned by 180° (true closures accepted without this check, benchmarks/loops.py: "
        "at most 1.3°/100 m with vo odometry, 6.8°/100 m with heavy)",
    )
    yaw_drift_per_100m: float = Field(
        3.0,
        ge=0,
        le=360,
        description="degrees per 100 m travelled since the stored keyframe, added to max_yaw_drift_deg",
    )
    place_radius: float = Field(
        20.0,
        ge=0,
        le=1000,
        description="a retrieved keyframe is matched as a place: with the stored keyframes of its pass whose robot "
        "poses lie this close to its own, their objects merged (loop.places); 0: the keyframe alone",
    )
    query_radius: float = Field(
        10.0,
        ge=0,
        le=1000,
        description="the query is the new keyframe with the keyframes just before it whose robot poses lie this "
        "close to its own, their objects merged, m; 0: the new keyframe alone",
    )
    ambiguity_bits: float = Field(
        8.0,
        ge=0,
        le=1e4,
        description="when two places that the fits put more than consistent_distance apart both verify, the best "
        "must carry this much more evidence, bits, or the keyframe relocalises nowhere (a repeated layout)",
    )
    exclude_recent_distance: float = Field(60.0, ge=0, le=1e6, description="never match keyframes from the last metres")
    search_radius: float = Field(
        15.0, gt=0, le=1e5, description="candidates lie this close to the estimated position, m"
    )
    search_radius_per_metre: float = Field(
        0.1, ge=0, le=10, description="plus this share of the distance travelled since the candidate (odometry drift)"
    )
    drift_radius: float = Field(
        15.0,
        gt=0,
        le=1e5,
        description="with tolerances covariance: how far the odometry may have drifted from a stored keyframe, m, "
        "taken as three standard deviations by the evidence's drift prior (a fit that moves the robot by d costs "
        "4.5 (d / R)² / ln 2 bits); the search radius only bounds which keyframes are candidates, so that opening "
        "it to the whole map does not make a distant look-alike as likely as a near place",
    )
    drift_radius_per_metre: float = Field(
        0.1, ge=0, le=10, description="plus this share of the distance travelled since the stored keyframe"
    )
    candidates: int = Field(
        10, gt=0, le=1000, description="best retrieval candidates that are matched in full, as distinct places"
    )
    retrieval: Literal["triangles", "signature"] = Field(
        "triangles",
        description="how the eligible keyframes are ranked: triangles, by the object triangles they share with the "
        "query (geometric hashing, loop.triangles); signature, by a histogram of labels and pairwise distances",
    )
    min_shared_triangles: int = Field(
        1,
        ge=0,
        le=10_000,
        description="with retrieval triangles: a retrieved place is matched only if one of its keyframes shares "
        "this many triangle keys with the query (of true relocalisations on simulated drives, 0.1 % share none)",
    )
    triangle_side_bin: float = Field(
        1.0, gt=0, le=100, description="retrieval triangles: sides are rounded to bins this wide, m"
    )
    triangle_objects: int = Field(
        12,
        ge=3,
        le=40,
        description="retrieval triangles: of this many objects nearest a keyframe's current object (12: 220 triangles)",
    )
    triangle_max_side: float = Field(
        40.0, gt=0, le=500, description="retrieval triangles: none with a side longer than this, m"
    )
    power_iterations: int = Field(
        50,
        gt=0,
        le=10_000,
        description="at most this many products of the power iteration (spectral matching): keyframes of one place "
        "converge in about 16 (99 % within 35 on the simulated KITTI drives); those that need more have no "
        "dominant consistent group, the case that verification rejects",
    )
    power_tolerance: float = Field(
        1e-5,
        gt=0,
        le=1,
        description="the power iteration stops once no entry moves more than this: only the order of the entries "
        "is used, and it is settled long before",
    )
    consecutive: int = Field(
        2, gt=0, le=100, description="accept only when this many consecutive keyframes relocalise consistently"
    )
    consistent_distance: float = Field(
        2.0, gt=0, le=1000, description="consecutive relocalisations put the robot within this of each other, m"
    )
    consistent_yaw_deg: float = Field(5.0, gt=0, le=180, description="and within this yaw, degrees")

    @model_validator(mode="after")
    def _triangle_sides_fit_their_bits(self) -> MatchingConfig:
        bins = self.triangle_max_side / self.triangle_side_bin
        if bins >= 2**TRIANGLE_SIDE_BITS:
            raise ValueError(
                f"triangle_max_side / triangle_side_bin is {bins:.4g} bins; a side's bin is held in "
                f"{TRIANGLE_SIDE_BITS} bits, so at most {2**TRIANGLE_SIDE_BITS - 1} bins fit"
            )
        return self


class ExperienceMapConfig(_Section):
    """Object experience map and its correction (paper 3.6, eq. 15-18)."""

    gc_distance_threshold: float = Field(
        7.0, gt=0, le=1000, description="max cell-space distance of a loop candidate, bins"
    )
    closure_gate: Literal["grid-cells", "drift", "none"] = Field(
        "drift",
        description="which closures the map accepts: grid-cells, the paper's check (the recognised experience's "
        "cells within gc_distance_threshold of the current); drift, that check widened by gc_drift_cells_per_100m "
        "for the metres the odometry has run since the robot last knew where it was (since the stored experience "
        "was made or the last accepted closure, whichever is fewer): the cells drift with the odometry, and under "
        "heavy drift the paper's check rejects true closures after a long loop (the default, with "
        "hebbian.recall_on accepted); none, every closure the detector accepted (benchmarks/gating.py compares them)",
    )
    gc_drift_cells_per_100m: float = Field(
        2.0,
        ge=0,
        le=1000,
        description="closure_gate drift: cells added to gc_distance_threshold per 100 m travelled since, cells "
        "(2: 16 m horizontally and 2 m vertically per 100 m; true closures on simulated KITTI drives with heavy "
        "odometry were up to 1.2 cells per 100 m apart, benchmarks/gating.py)",
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
    odometry_sigma_floor: float = Field(
        0.01, ge=1e-6, le=1000, description="pose graph: least translation std of a link, m"
    )
    loop_sigma: float = Field(0.5, ge=1e-6, le=1000, description="pose graph: std of a loop link's translation, m")
    loop_yaw_sigma: float = Field(0.02, ge=1e-6, le=10, description="pose graph: std of a loop link's yaw, rad")
    robust_kernel: Literal["huber", "cauchy", "none"] = Field("huber", description="pose graph: loop-link kernel")
    robust_threshold: float = Field(3.0, gt=0, le=1000, description="pose graph: kernel scale, in standard deviations")
    object_landmarks: bool = Field(
        False,
        description="pose graph: the object map's confirmed objects become landmarks (a Point3 each, a bearing-range "
        "factor per (object, experience) observation sum) and the graph is solved incrementally by iSAM2 as "
        "experiences and observations arrive (neoslam.mapping.landmarks); a view of a landmark made more than "
        "localised_distance ago counts only while the robot knows where it is (associations by a drifted pose are "
        "guesses). False: today's pose graph, solved at loops",
    )
    landmark_noise: Literal["per-view", "summed"] = Field(
        "per-view",
        description="object landmarks: the noise of an (object, experience) observation sum; per-view, that of one of "
        "its views (the depth std of the inverse-variance mean view along the ray, object_map.position_sigma_floor "
        "across it): views from one experience share the visible surface and the odometry since the experience "
        "began, so their errors do not average out; summed, the inverse of the summed weight (independent views)",
    )
    landmark_robust_kernel: Literal["huber", "cauchy", "none"] = Field(
        "cauchy",
        description="object landmarks: kernel of the observation factors (a wrong association must not "
        "bend the map: Cauchy's weight falls with the square of the residual, Huber's only linearly)",
    )
    landmark_robust_threshold: float = Field(
        3.0, gt=0, le=1000, description="object landmarks: kernel scale, in standard deviations"
    )
    landmark_centre_sigma: float = Field(
        2.0,
        ge=0,
        le=100,
        description="object landmarks: std of an observation's centre along its ray in the ground plane, beyond the "
        "stereo depth std, in radii of the class's footprint (keyframes.footprints) along the ray: the centre was "
        "shifted a radius from the visible surface to the object's middle, and where the object's orientation and "
        "extent are unknown (or the detector's centres are biased otherwise) the shift may be wrong by a radius for "
        "every view alike, a bias no noise averages out: a straight drive whose centres are already the middles "
        "ends 2.3 m (1.5 %) long at 1 radius, 1.1 m at 2, 0.4 m at 4, while simulated KITTI keeps less of the "
        "landmarks' gain the larger it is (benchmarks/landmarks.py); 0: the shift is taken as exact",
    )
    landmark_height_sigma: float = Field(
        2.0,
        gt=0,
        le=10,
        description="object landmarks: std of an observation's centre in height, m (at least "
        "object_map.position_sigma_floor): object heights from stereo boxes are poor, and a landmark must not pull "
        "the map up or down",
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
        "keyframe nearest to a new one on a street driven again is within a spacing; at 3 m, passes of KITTI 00 "
        "still stored keyframes 3-4 m from a stored one)",
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
        "where the map has it (ground plane), m (3 loop_sigma); otherwise the map is off (the robot comes back after "
        "a long loop) and the keyframe is stored with a new experience and a loop link that corrects it, as the "
        "paper does",
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


class ObjectMapConfig(_Section):
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
        "matching.max_vertical_offset): the association radius holds in the ground plane, where objects stand apart; "
        "the pose's height and pitch drift move a view 50 m away up or down by 2 m and more, while objects rarely "
        "stand above each other (a bridge)",
    )
    tentative_distance: float = Field(
        60.0,
        gt=0,
        le=1e6,
        description="an object seen fewer than min_observations times is forgotten after this much travel without "
        "another sighting, m (keyframes.window_length): a false detection, or an object glimpsed once a pass, would "
        "otherwise pile up into an object on a street driven every day",
    )


class MovingObjectsConfig(_Section):
    """Moving objects kept out of keyframes and the object map (beyond the paper): short tracks of each object's
    observations in the odometry frame (locally accurate), and a weighted fit of position against time; a track
    whose velocity is significant against its uncertainty and fast enough is moving. The depth std of an
    observation is the object map's (object_map.depth_sigma_at_1m, position_sigma_floor)."""

    enabled: bool = Field(
        True,
        description="detect moving objects; their observations join no keyframe and no map object, and objects.csv "
        "lists them with moving = 1 (on static simulated streets loop precision, recall and ATE as without it; "
        "with traffic it is what keeps loop closure working: benchmarks/moving.py)",
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
        "is held out of keyframes and the map until it is judged (significance_sigmas or more: never held). "
        "Measured on simulated KITTI 05 and 00 (benchmarks/moving.py): 2 keeps more traffic out and closes more "
        "loops with traffic but cost static 05 loop recall (0.64 -> 0.51); 3 leaves static streets as they were",
    )
    min_speed: float = Field(
        2.0,
        ge=0,
        le=100,
        description="and at least this fast, m/s: below, odometry's local error and the visible surface changing "
        "with the view. Under heavy odometry noise (simulated `heavy`: 0.1 rad/s of yaw-rate noise) a parked car 30 m "
        "off seems to move about 1 m/s; at 0.7 m/s the detector flagged parked objects there and no loop closed on "
        "static KITTI 05 and 06 (45.5 and 41.9 m against 9.0 and 3.5 m at 2.0), before the tracks allowed for the "
        "odometry's noise (odometry_heading_noise). Walkers (1.0-1.8 m/s) have their own (label_min_speed). With "
        "`vo` odometry at 1.0 (benchmarks/moving.py, KITTI 05 / 00) parked objects flagged stayed at 0.015 / 0.011 "
        "of their views and loop recall as at 2.0 (0.30 against 0.32 on 00 with traffic)",
    )
    label_min_speed: dict[str, Annotated[float, Field(ge=0, le=100)]] = Field(
        {"person": 0.7},
        description="min_speed for these labels instead, m/s: a walker (1.0-1.8 m/s) stays below 2.0, is then known to "
        "be static, and a keyframe holding them does not match the place again (simulated KITTI 02, vo, 20 % moving, "
        "benchmarks/kitti_sim.py: a revisit lost, 18.6 m ATE with the motion detector against 9.5 m with person: 0.7)",
    )
    judge_after: int = Field(
        3, ge=2, le=1000, description="a track is judged from this many observations on (two fix no velocity)"
    )
    unjudged: Literal["join", "wait", "out"] = Field(
        "wait",
        description="the views of a track not found moving: join (keyframes take them as static); wait: a keyframe "
        "window object is provisional until one of its views belongs to a track known to be static (static_sigmas), "
        "and a provisional object missing where a keyframe match puts it is no contradiction (it is matched and "
        "counts in the share of objects to match as any other); out: a track's first judge_after - 1 views are "
        "kept out of keyframes and the map. Measured by benchmarks/moving.py (KITTI 05 / 00, vo, 20 % moving): "
        "loop recall 0.26 / 0.18 with join, 0.41 / 0.36 with wait (static streets 0.60 / 0.60 -> 0.66 / 0.64): a "
        "car's track that broke off before it was judged, or a car coming on whose first views show neither, left "
        "a window object that stopped its keyframes matching the place again",
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
        "profile's 0.01 rad/s yaw-rate noise per 0.1 s frame; `heavy`: 0.032). Without it a parked car 30 m off "
        "seems to move under heavy odometry noise",
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
        description="tracks whose fitted speed is below this feed the estimate, m/s: traffic is faster; a parked car "
        "30 m off seems to move about 1 m/s under the simulated `heavy` odometry (leaving out every track found "
        "moving instead left out those, and the estimate of 0.032 rad heading noise came out at 0.014-0.021). At 4.0 "
        "slow cars raised it (simulated KITTI 05 / 06 `heavy`, all three kitti_sim.py steps, static and 20 % moving: "
        "5.50 / 2.69 / 5.71 / 8.42 m against 6.38 / 1.84 / 5.23 / 3.28 m at 2.0)",
    )
    noise_window: int = Field(1000, ge=1, le=1_000_000, description="views kept for the estimate (the latest)")
    noise_min_views: int = Field(
        20,
        ge=1,
        le=1_000_000,
        description="views held before the estimate is used (the floors alone until then): parked cars flagged in "
        "those first frames stay so, and a drive that loops back to its start misses them (simulated KITTI 06, "
        "`heavy`: 7 closures at 100, 16 at 30, 18 at 20 and 10, 22 with `heavy`'s noise stated; `vo` with traffic: "
        "the same at 20 as at 100)",
    )
    noise_bins: int = Field(
        4,
        ge=2,
        le=100,
        description="groups of views by distance from the robot: the heading error moves far objects more, the "
        "position error all alike (a line through the groups' variances separates them)",
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


class MapStoreConfig(_Section):
    """A map kept in a file over several sessions (`neoslam run --map FILE`, beyond the paper)."""

    synchronous: Literal["full", "normal"] = Field(
        "full",
        description="SQLite's synchronous setting for the map file (write-ahead log): full makes every committed "
        "keyframe survive a power cut too; normal survives a killed process and keeps the file consistent after a "
        "power cut, which may lose the last commits",
    )
    relocalisation_candidates: int = Field(
        20,
        gt=0,
        le=100_000,
        description="until a session has joined the stored map, each keyframe is matched in full against this many "
        "stored places, the best the retrieval (matching.retrieval) ranks over the whole map (its pose relative to "
        "the map is unknown)",
    )
    relocalisation_consecutive: int = Field(
        3,
        gt=0,
        le=100,
        description="a session joins the stored map only when this many consecutive keyframes relocalise in it "
        "consistently (matching.consecutive within a session): a search over the whole map meets more look-alike "
        "places than a drift-bounded one, and a wrong relocalisation is worse than none",
    )


class MotionLimitsConfig(_Section):
    """Motion no road vehicle makes: an input that claims it (frames.csv velocities, an --odometry pose file, a
    `simulate --trajectory` file) is refused with its file, line and value, instead of being integrated. It keeps
    a wrong value (a unit slip, a corrupt line, 1e300) from becoming a map, and every frame's work bounded."""

    max_speed: float = Field(
        70.0,
        gt=0,
        le=1000,
        description="largest speed between two frames, m/s (70 m/s = 252 km/h; KITTI's ground truth: 26 m/s at most)",
    )
    max_turn_rate: float = Field(
        3.0,
        gt=0,
        le=100,
        description="largest rotation rate between two frames (about any axis), rad/s: about half a turn a second; "
        "KITTI's ground truth turns at 0.81 rad/s at most, and the paper-max odometry noise (0.5 rad/s std) reaches "
        "it once in 5e8 frames",
    )
    max_time_step: float = Field(
        10.0,
        gt=0,
        le=86400,
        description="largest time between two frames, s (KITTI: 0.1 s): across a longer gap the recording stopped, "
        "and integrating a velocity over it means nothing",
    )


class EvaluationConfig(_Section):
    """How results are judged against ground truth (never read by the SLAM path)."""

    loop_max_distance: float = Field(5.0, gt=0, le=1e4, description="a true closure's frames are this close, m")
    loop_min_frame_gap: int = Field(100, ge=0, le=10_000_000, description="and at least this many frames apart")
    loop_distance: Literal["3d", "horizontal"] = Field(
        "horizontal",
        description="distance of that test: horizontal, since KITTI 02 and 08 ground truth disagree by up to 5.8 m "
        "in height where a road is driven again; or 3d",
    )
    alignment: Literal["se3", "sim3", "none"] = Field("se3", description="alignment before ATE")
    rpe_delta: float = Field(100.0, gt=0, le=1e6, description="RPE pair spacing")
    rpe_unit: Literal["frames", "m"] = Field("m", description="unit of rpe_delta")
    max_time_difference: float = Field(0.01, gt=0, le=1000, description="timestamp association tolerance, s")


# The sections that shape a map (the cells, keyframes, matching and the maps): a map file is extended only with the
# values it was made with (neoslam.store), and a sweep's cells that differ in these alone share one simulation.
MAP_SECTIONS = (
    "grid_cells",
    "head_direction",
    "object_vector",
    "hebbian",
    "keyframes",
    "matching",
    "experience_map",
    "object_map",
    "moving_objects",
)


class NeoSLAMConfig(_Section):
    """Everything, one section per component."""

    perception: PerceptionConfig = PerceptionConfig()
    simulator: SimulatorConfig = Field(default_factory=SimulatorConfig)
    grid_cells: GridCellConfig = GridCellConfig()
    head_direction: HeadDirectionConfig = HeadDirectionConfig()
    object_vector: ObjectVectorConfig = ObjectVectorConfig()
    hebbian: HebbianConfig = HebbianConfig()
    keyframes: KeyframeConfig = KeyframeConfig()
    matching: MatchingConfig = MatchingConfig()
    experience_map: ExperienceMapConfig = ExperienceMapConfig()
    object_map: ObjectMapConfig = ObjectMapConfig()
    moving_objects: MovingObjectsConfig = MovingObjectsConfig()
    map_store: MapStoreConfig = MapStoreConfig()
    evaluation: EvaluationConfig = EvaluationConfig()
    motion_limits: MotionLimitsConfig = MotionLimitsConfig()


def _env_overrides(environ: dict[str, str]) -> dict[str, Any]:
    """Nested dict from NEOSLAM_SECTION__FIELD[__FIELD] variables; values parsed as YAML scalars."""
    overrides: dict[str, Any] = {}
    for key, raw in sorted(environ.items()):
        if not key.startswith(ENV_PREFIX) or ENV_NESTED_DELIMITER not in key:
            continue  # NEOSLAM_DATA and friends are not configuration
        path = key[len(ENV_PREFIX) :].lower().split(ENV_NESTED_DELIMITER)
        node = overrides
        for part in path[:-1]:
            node = node.setdefault(part, {})
            if not isinstance(node, dict):  # NEOSLAM_A__B=1 and NEOSLAM_A__B__C=2: B cannot be both
                raise ConfigError(f"environment variable {key}: {part} is set as a value by another variable")
        node[path[-1]] = _parse_scalar(raw)
    return overrides


def _parse_scalar(raw: str) -> Any:
    """A YAML scalar or list ("0.3", "true", "[36, 36, 36]"); text that is not YAML stays a string, so that
    validation names the field instead of the YAML parser failing."""
    try:
        return yaml.safe_load(raw) if raw.strip() else raw
    except yaml.YAMLError:
        return raw


def merge_settings(base: Mapping[str, Any], override: Mapping[str, Any]) -> dict[str, Any]:
    """`override` over `base`, section by section (nested mappings merged, other values replaced)."""
    merged = dict(base)
    for key, value in override.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = merge_settings(merged[key], value)
        else:
            merged[key] = value
    return merged


def describe_validation_error(error: ValidationError) -> str:
    """The first problem of a validation as `section.field: reason (got value)`, for a one-line message."""
    first = error.errors()[0]
    where = ".".join(str(part) for part in first["loc"])
    reason = first["msg"].removeprefix("Value error, ")
    given = first.get("input")
    if isinstance(given, bool | int | float | str) and len(repr(given)) <= 40 and first["type"] != "extra_forbidden":
        reason += f" (got {given!r})"
    return f"{where}: {reason}" if where else reason


def _variable_for(location: tuple[Any, ...], environ: dict[str, str]) -> str:
    """The NEOSLAM_* variable that set the value at `location` (or under it: NEOSLAM_FOO__BAR for an unknown
    section foo), as the user spelled it."""
    wanted = tuple(str(part) for part in location)
    for key in sorted(environ):
        if not key.startswith(ENV_PREFIX) or ENV_NESTED_DELIMITER not in key:
            continue
        path = tuple(key[len(ENV_PREFIX) :].lower().split(ENV_NESTED_DELIMITER))
        if wanted[: len(path)] == path or path[: len(wanted)] == wanted:
            return key
    return ENV_PREFIX + ENV_NESTED_DELIMITER.join(wanted).upper()


def _read_yaml_mapping(path: Path) -> dict[str, Any]:
    """A config file's sections: one error naming the file (and the line, where YAML knows it) otherwise."""
    if not path.is_file():
        raise InputError(path, "config file not found")
    loaded = read_yaml(path) or {}
    if not isinstance(loaded, dict):
        raise InputError(path, "a config file must hold a mapping of sections")
    return loaded


def config_values(path: Path | None = None, environ: Mapping[str, str] | None = None) -> dict[str, Any]:
    """The settings a YAML file and then NEOSLAM_* environment variables give over the defaults, as a mapping
    (checked: a bad value is a ConfigError naming the file or the variable), for callers that merge more on top."""
    values = _read_yaml_mapping(path) if path is not None else {}
    variables = dict(os.environ if environ is None else environ)
    merged = merge_settings(values, _env_overrides(variables))
    try:
        NeoSLAMConfig.model_validate(values)
    except ValidationError as error:
        raise ConfigError(f"{path or 'configuration'}: {describe_validation_error(error)}") from None
    try:
        NeoSLAMConfig.model_validate(merged)
    except ValidationError as error:
        variable = _variable_for(error.errors()[0]["loc"], variables)
        raise ConfigError(f"environment variable {variable}: {describe_validation_error(error)}") from None
    return merged


def load_config(path: Path | None = None, environ: Mapping[str, str] | None = None) -> NeoSLAMConfig:
    """Defaults, then the YAML file, then NEOSLAM_* environment variables."""
    return NeoSLAMConfig.model_validate(config_values(path, environ))


def dump_config(config: NeoSLAMConfig) -> str:
    """The resolved configuration as YAML, sections in declaration order."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
