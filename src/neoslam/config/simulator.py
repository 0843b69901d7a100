"""The simulator's settings: a seed, the camera, and named profiles of the detector and the odometry."""

from __future__ import annotations

from typing import Any

from pydantic import Field, model_validator

from neoslam.config.base import Section
from neoslam.config.calibration import with_detection_profile
from neoslam.config.sensors import CameraConfig
from neoslam.config.simulated_world import DetectionNoiseConfig, OdometryNoiseConfig, WorldConfig

__all__ = ["SimulatorConfig"]


class SimulatorConfig(Section):
    """`neoslam simulate`: world, camera, detection and odometry noise."""

    seed: int = Field(0, ge=0, le=2**63 - 1, description="seed of every random draw of a simulation")
    camera: CameraConfig = CameraConfig()
    world: WorldConfig = WorldConfig()
    detection: DetectionNoiseConfig = DetectionNoiseConfig()
    detection_profile: str = Field(
        "real",
        description="named detection model and street (neoslam.config.calibration): real, calibrated to the real "
        "front end on KITTI 06; ideal, a richer street and detector. It fills `detection` and `world`; fields given "
        "there override it",
    )
    noise_profile: str = Field(
        "vo",
        description="name of the odometry noise profile that `odometry` holds: none, vo, heavy or paper-max "
        "(`neoslam simulate --noise` sets both)",
    )
    odometry: OdometryNoiseConfig = OdometryNoiseConfig()
    frame_period: float = Field(
        0.1037, ge=0.001, le=10, description="s between frames when no times are given (KITTI mean)"
    )

    @model_validator(mode="before")
    @classmethod
    def _apply_detection_profile(cls, data: Any) -> Any:
        return with_detection_profile(data) if isinstance(data, dict) else data
