"""A configuration with named simulator profiles applied: the one place where a profile name becomes values."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel

from neoslam.config.calibration import detection_profile, noise_profile
from neoslam.config.system import NeoSLAMConfig
from neoslam.errors import ConfigError

__all__ = ["simulation_config"]


def simulation_config(
    config: NeoSLAMConfig, noise: str | None, seed: int | None, detector: str | None = None
) -> NeoSLAMConfig:
    """The config with a named odometry noise profile, a named detection profile (its detection and street values
    replace the config's profile's, the values the config file set itself stay: a share of moving objects, say)
    and a seed applied to its simulator section."""
    update: dict[str, Any] = {}
    try:
        if noise is not None:
            update |= {"noise_profile": noise, "odometry": noise_profile(noise)}
        if detector is not None:
            profile, current = detection_profile(detector), detection_profile(config.simulator.detection_profile)
            update |= {
                "detection_profile": detector,
                "detection": _profile_with_own_values(profile.detection, current.detection, config.simulator.detection),
                "world": _profile_with_own_values(profile.world, current.world, config.simulator.world),
            }
    except ValueError as error:
        raise ConfigError(str(error)) from None
    if seed is not None:
        update["seed"] = seed
    return config.model_copy(update={"simulator": config.simulator.model_copy(update=update)})


def _profile_with_own_values(profile: BaseModel, current: BaseModel, section: BaseModel) -> BaseModel:
    """A profile's section with the values in which the config's section differs from its own profile's."""
    own = {name: value for name, value in section if value != getattr(current, name)}
    return profile.model_copy(update=own)
