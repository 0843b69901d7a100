"""Visual odometry from the true motion: body-frame velocities with the noise of a chosen profile."""

from __future__ import annotations

import numpy as np

from neoslam.config import OdometryNoiseConfig
from neoslam.geometry import body_velocities
from neoslam.types import Trajectory

__all__ = ["noisy_odometry"]

STANDSTILL_SPEED = 1e-3  # m/s: below this the direction of motion is taken as the robot's x axis


def noisy_odometry(truth: Trajectory, noise: OdometryNoiseConfig, rng: np.random.Generator):
    """(n, 3) linear and (n, 3) angular body velocities of each step i-1 -> i (row 0 zero), with noise:
    speed scaled by (1 + bias) plus N(0, σ_v) along the motion, yaw rate plus bias plus N(0, σ_ω),
    pitch rate plus N(0, σ_pitch), vertical speed plus N(0, σ_vz)."""
    linear, angular = body_velocities(truth.poses, truth.timestamps)
    steps = len(truth) - 1
    speed = np.linalg.norm(linear[1:], axis=1, keepdims=True)
    direction = np.where(speed > STANDSTILL_SPEED, linear[1:] / np.maximum(speed, STANDSTILL_SPEED), [1.0, 0, 0])
    speed_noise = _gaussian(rng, noise.sigma_speed, steps)[:, None]
    linear[1:] = linear[1:] * (1.0 + noise.speed_scale_bias) + direction * speed_noise
    linear[1:, 2] += _gaussian(rng, noise.sigma_vertical_speed, steps)
    angular[1:, 2] += noise.yaw_rate_bias + _gaussian(rng, noise.sigma_yaw_rate, steps)
    angular[1:, 1] += _gaussian(rng, noise.sigma_pitch_rate, steps)
    return linear, angular


def _gaussian(rng: np.random.Generator, sigma: float, count: int) -> np.ndarray:
    # Always draw, so that switching one noise off leaves the other noises' draws unchanged.
    return sigma * rng.standard_normal(count)
