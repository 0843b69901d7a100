"""What the simulator draws: the street's objects, the detector's errors and the odometry's noise."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator, model_validator

from neoslam.config.base import Section

__all__ = ["WorldConfig", "DetectionNoiseConfig", "OdometryNoiseConfig"]


class WorldConfig(Section):
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


class DetectionNoiseConfig(Section):
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


class OdometryNoiseConfig(Section):
    """Noise of the visual odometry, applied to the true per-frame motion."""

    sigma_speed: float = Field(0.2, ge=0, le=100, description="std of the forward speed, m/s, per frame")
    sigma_yaw_rate: float = Field(0.01, ge=0, le=10, description="std of the yaw rate, rad/s, per frame")
    speed_scale_bias: float = Field(0.01, ge=-1, le=10, description="relative speed error, +0.01 = 1 % too long")
    yaw_rate_bias: float = Field(0.001, ge=-10, le=10, description="constant yaw-rate error, rad/s")
    sigma_vertical_speed: float = Field(0.02, ge=0, le=100, description="std of the vertical speed, m/s")
    sigma_pitch_rate: float = Field(0.002, ge=0, le=10, description="std of the pitch rate, rad/s")
