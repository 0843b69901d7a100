"""Visual odometry from the true motion: body-frame velocities with the noise of a chosen profile, for a whole
trajectory at once or a step at a time (a robot driven in closed loop, whose next pose is not known in advance)."""

from __future__ import annotations

import numpy as np

from neoslam.config import OdometryNoiseConfig
from neoslam.geometry import body_velocities
from neoslam.types import Trajectory

__all__ = ["noisy_odometry", "noisy_step"]

STANDSTILL_SPEED = 1e-3  # m/s: below this the direction of motion is taken as the robot's x axis


def noisy_odometry(truth: Trajectory, noise: OdometryNoiseConfig, rng: np.random.Generator):
    """(n, 3) linear and (n, 3) angular body velocities of each step i-1 -> i (row 0 zero), with noise:
    speed scaled by (1 + bias) plus N(0, σ_v) along the motion, yaw rate plus bias plus N(0, σ_ω),
    pitch rate plus N(0, σ_pitch), vertical speed plus N(0, σ_vz)."""
    linear, angular = body_velocities(truth.poses, truth.timestamps)
    linear[1:], angular[1:] = _with_noise(linear[1:], angular[1:], noise, rng)
    return linear, angular


def noisy_step(
    previous: np.ndarray, current: np.ndarray, dt: float, noise: OdometryNoiseConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(3,) linear and (3,) angular body velocities of one step between two true poses T_world_robot, `dt` seconds
    apart, with the noise model of noisy_odometry (one draw of each noise per step)."""
    linear, angular = body_velocities(np.stack([previous, current]), np.array([0.0, dt]))
    noisy_linear, noisy_angular = _with_noise(linear[1:], angular[1:], noise, rng)
    return noisy_linear[0], noisy_angular[0]


def _with_noise(
    linear: np.ndarray, angular: np.ndarray, noise: OdometryNoiseConfig, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) true linear and angular velocities of k steps with the profile's noise added (new arrays)."""
    steps = len(linear)
    speed = np.linalg.norm(linear, axis=1, keepdims=True)
    direction = np.where(speed > STANDSTILL_SPEED, linear / np.maximum(speed, STANDSTILL_SPEED), [1.0, 0, 0])
    speed_noise = _gaussian(rng, noise.sigma_speed, steps)[:, None]
    linear = linear * (1.0 + noise.speed_scale_bias) + direction * speed_noise
    linear[:, 2] += _gaussian(rng, noise.sigma_vertical_speed, steps)
    angular = angular.copy()
    angular[:, 2] += noise.yaw_rate_bias + _gaussian(rng, noise.sigma_yaw_rate, steps)
    angular[:, 1] += _gaussian(rng, noise.sigma_pitch_rate, steps)
    return linear, angular


def _gaussian(rng: np.random.Generator, sigma: float, count: int) -> np.ndarray:
    # Always draw, so that switching one noise off leaves the other noises' draws unchanged.
    return sigma * rng.standard_normal(count)
