"""Pose-graph back end: corrects the experience map by nonlinear least squares (GTSAM), beyond the paper.

The paper (3.6, eq. 18) relaxes the map by nudging linked experiences towards each other. This back end instead
solves for all poses at once: one Pose3 per experience, a between-factor per link, weighted by how far and how long
the robot travelled (odometry) or by the closure's accuracy (loop), and a robust kernel on the loop links so that one
wrong closure cannot bend the whole map.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from neoslam.config import ExperienceMapConfig
from neoslam.mapping.graph import MapGraph
from neoslam.types import Link

__all__ = [
    "LoopResidual",
    "OdometryNoise",
    "PoseGraphReport",
    "link_noise_model",
    "link_sigmas",
    "optimise_pose_graph",
    "poses_from_values",
]

OdometryNoise = tuple[float, float]  # heading (rad) and position (m) random walks per root second

# Roll and pitch are observable from gravity, so links hold them tightly whatever the distance travelled.
ROLL_PITCH_SIGMA_RAD = 0.01
# A short or stationary odometry link still carries some heading noise; without a floor its yaw would be rigid.
ODOMETRY_YAW_SIGMA_FLOOR_RAD = 1e-3
# Node 0 defines the world frame: a prior this tight pins it without making the system singular.
ANCHOR_SIGMA = 1e-6
# A loop link whose whitened residual exceeds this many standard deviations after optimisation is one the robust
# kernel has mostly ignored (a Cauchy kernel at 1 sigma gives it a weight of 0.1 or less).
OUTLIER_SIGMAS = 3.0
# Levenberg-Marquardt stopping rules: tight enough for centimetre maps, loose enough to stop in a few iterations.
MAX_ITERATIONS = 100
RELATIVE_ERROR_TOLERANCE = 1e-6
ABSOLUTE_ERROR_TOLERANCE = 1e-9

# GTSAM orders a Pose3 tangent vector rotation first (roll, pitch, yaw about the body axes), then translation.
_ROTATION = slice(0, 3)
_TRANSLATION = slice(3, 6)
_YAW = 2


@dataclass(frozen=True, slots=True)
class LoopResidual:
    """How well one loop link agrees with the optimised map."""

    link_index: int  # into graph.links
    translation_m: float  # where the link puts its target vs where the target is
    sigmas: float  # norm of the whitened 6-D error, before the robust kernel
    kernel_weight: float  # weight the robust kernel gives it at the solution (1 without a kernel)

    @property
    def is_outlier(self) -> bool:
        return self.sigmas > OUTLIER_SIGMAS


@dataclass(frozen=True, slots=True)
class PoseGraphReport:
    """What one optimisation did: LM iterations, total factor error before and after, and each loop link's fit."""

    iterations: int
    initial_error: float
    final_error: float
    loops: tuple[LoopResidual, ...]

    @property
    def outlier_links(self) -> tuple[int, ...]:
        """Loop links the map disagrees with by more than OUTLIER_SIGMAS: the ones a robust kernel down-weighted."""
        return tuple(loop.link_index for loop in self.loops if loop.is_outlier)


def optimise_pose_graph(
    graph: MapGraph, config: ExperienceMapConfig, noise: OdometryNoise | None = None
) -> PoseGraphReport:
    """Correct graph.poses in place by Levenberg-Marquardt over the links in use; node 0 stays where it is. `noise`:
    the odometry's per root second (see link_sigmas)."""
    if len(graph) == 0:
        return PoseGraphReport(iterations=0, initial_error=0.0, final_error=0.0, loops=())
    live = graph.live()
    factors, sigmas = _build_factors(graph, live, config, noise)
    initial = _initial_values(graph.poses)
    optimiser = gtsam.LevenbergMarquardtOptimizer(factors, initial, _lm_parameters())
    result = optimiser.optimize()
    graph.poses[:] = poses_from_values(result, len(graph))
    return PoseGraphReport(
        iterations=optimiser.iterations(),
        initial_error=factors.error(initial),
        final_error=factors.error(result),
        loops=_loop_residuals(graph, live, factors, sigmas, result, config),
    )


def _build_factors(
    graph: MapGraph, live: list[int], config: ExperienceMapConfig, noise: OdometryNoise | None
) -> tuple[gtsam.NonlinearFactorGraph, np.ndarray]:
    """The factor graph (anchor prior at index 0, then one between-factor per link in use, `live`) and each such
    link's sigmas."""
    factors = gtsam.NonlinearFactorGraph()
    anchor_noise = gtsam.noiseModel.Isotropic.Sigma(6, ANCHOR_SIGMA)
    factors.add(gtsam.PriorFactorPose3(0, gtsam.Pose3(graph.poses[0]), anchor_noise))
    links = [graph.links[index] for index in live]
    sigmas = np.array([link_sigmas(link, config, noise) for link in links]).reshape(-1, 6)
    for link, link_sigma in zip(links, sigmas, strict=True):
        model = _noise_model(link, link_sigma, config)
        factors.add(gtsam.BetweenFactorPose3(link.source, link.target, gtsam.Pose3(link.relative), model))
    return factors, sigmas


def link_sigmas(link: Link, config: ExperienceMapConfig, noise: OdometryNoise | None = None) -> np.ndarray:
    """Standard deviations of a link in GTSAM's tangent order (roll, pitch, yaw, x, y, z). An odometry link's grow
    with the metres it spans at the configured rates and, given the odometry's `noise` (heading rad, position m per
    root second), with its seconds at those: whichever is larger (a robot that stands still drifts too)."""
    sigmas = np.empty(6)
    sigmas[_ROTATION] = ROLL_PITCH_SIGMA_RAD
    if link.kind == "loop":
        sigmas[_YAW] = config.loop_yaw_sigma
        sigmas[_TRANSLATION] = config.loop_sigma
    else:  # odometry error is a random walk: its std grows with the square root of the distance travelled
        root = np.sqrt(link.distance_m)
        sigmas[_YAW] = max(ODOMETRY_YAW_SIGMA_FLOOR_RAD, config.odometry_yaw_sigma_per_root_metre * root)
        sigmas[_TRANSLATION] = max(config.odometry_sigma_floor, config.odometry_sigma_per_root_metre * root)
        if noise is not None:
            root_s = np.sqrt(link.duration_s)
            sigmas[_YAW] = max(sigmas[_YAW], noise[0] * root_s)
            sigmas[_TRANSLATION] = np.maximum(sigmas[_TRANSLATION], noise[1] * root_s)
    return sigmas


def link_noise_model(
    link: Link, config: ExperienceMapConfig, noise: OdometryNoise | None = None
) -> gtsam.noiseModel.Base:
    """The noise model of a link's between-factor: its sigmas (see link_sigmas), a robust kernel on a loop link."""
    return _noise_model(link, link_sigmas(link, config, noise), config)


def _noise_model(link: Link, sigmas: np.ndarray, config: ExperienceMapConfig) -> gtsam.noiseModel.Base:
    """Gaussian for odometry; for a loop link, wrapped in the configured robust kernel (a closure may be wrong)."""
    gaussian = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    kernel = _robust_kernel(config)
    if link.kind != "loop" or kernel is None:
        return gaussian
    return gtsam.noiseModel.Robust.Create(kernel, gaussian)


def _robust_kernel(config: ExperienceMapConfig) -> gtsam.noiseModel.mEstimator.Base | None:
    """The M-estimator for loop links; its threshold is in whitened units, i.e. standard deviations."""
    if config.robust_kernel == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(config.robust_threshold)
    if config.robust_kernel == "cauchy":
        return gtsam.noiseModel.mEstimator.Cauchy.Create(config.robust_threshold)
    return None


def _lm_parameters() -> gtsam.LevenbergMarquardtParams:
    parameters = gtsam.LevenbergMarquardtParams()
    parameters.setMaxIterations(MAX_ITERATIONS)
    parameters.setRelativeErrorTol(RELATIVE_ERROR_TOLERANCE)
    parameters.setAbsoluteErrorTol(ABSOLUTE_ERROR_TOLERANCE)
    return parameters


def _initial_values(poses: np.ndarray) -> gtsam.Values:
    values = gtsam.Values()
    for index, pose in enumerate(poses):
        values.insert(index, gtsam.Pose3(pose))
    return values


def poses_from_values(values: gtsam.Values, count: int) -> np.ndarray:
    """(count, 4, 4) poses from Values keyed 0..count-1; extractPose3 gives rows of [R row-major (9), t (3)]."""
    rows = gtsam.utilities.extractPose3(values)
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, :3, :3] = rows[:, :9].reshape(count, 3, 3)
    poses[:, :3, 3] = rows[:, 9:]
    return poses


def _loop_residuals(
    graph: MapGraph,
    live: list[int],
    factors: gtsam.NonlinearFactorGraph,
    sigmas: np.ndarray,
    values: gtsam.Values,
    config: ExperienceMapConfig,
) -> tuple[LoopResidual, ...]:
    """Residual of each loop link in use at the solution; factor i + 1 is link live[i] (factor 0 is the anchor)."""
    translation = graph.link_residuals()
    kernel = _robust_kernel(config)
    residuals = []
    for factor, index in enumerate(live):
        if graph.links[index].kind != "loop":
            continue
        error = factors.at(factor + 1).unwhitenedError(values)
        whitened = float(np.linalg.norm(error / sigmas[factor]))
        weight = 1.0 if kernel is None else float(kernel.weight(whitened))
        residuals.append(LoopResidual(index, float(translation[index]), whitened, weight))
    return tuple(residuals)
