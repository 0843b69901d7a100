"""The stereo camera and the motion a road vehicle can make (inputs claiming more are refused)."""

from __future__ import annotations

from pydantic import Field

from neoslam.config.base import Section

__all__ = ["CameraConfig", "MotionLimitsConfig"]


class CameraConfig(Section):
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


class MotionLimitsConfig(Section):
    """Motion no road vehicle makes: an input that claims it (frames.csv velocities, an --odometry pose file, a
    `simulate --trajectory` file) is refused with its file, line and value, instead of being integrated. It keeps
    a wrong value (a unit slip, a corrupt line, 1e300) from becoming a map, and every frame's work bounded."""

    max_speed: float = Field(
        70.0,
        gt=0,
        le=1000,
        description="largest speed between two frames, m/s (70 m/s = 252 km/h, well above any road vehicle's)",
    )
    max_turn_rate: float = Field(
        3.0,
        gt=0,
        le=100,
        description="largest rotation rate between two frames (about any axis), rad/s: about half a turn a second, "
        "well above a road vehicle's turns and practically never reached by the paper-max odometry noise",
    )
    max_time_step: float = Field(
        10.0,
        gt=0,
        le=86400,
        description="largest time between two frames, s (KITTI: 0.1 s): across a longer gap the recording stopped, "
        "and integrating a velocity over it means nothing",
    )
