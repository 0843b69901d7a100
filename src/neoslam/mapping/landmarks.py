"""Objects as landmarks in the pose graph, solved incrementally by iSAM2 (beyond the paper).

Every static object seen from several experiences constrains their poses. The graph holds a Pose3 per experience
(keyed by its id) and a Point3 per confirmed object of the object map (keyed `l` + its id), a between-factor per
link (odometry and loop, as the batch pose graph weighs them, robust on loops) and a bearing-range factor per
(object, experience) observation sum: the mean of the object's views in the experience's frame. The noise of a
factor is the covariance of that mean point, carried into the factor's bearing (a Unit3 error in the tangent basis
GTSAM picks for the measured direction, which lies any way round the ray) and range:
- across the ray in the ground plane, the object map's `position_sigma_floor`: stereo places a view well across
  its ray;
- along the ray in the ground plane, the depth std of the sum's views (it grows with depth squared) and the
  uncertainty of the stereo centre's shift from the visible surface to the object's middle (keyframes'
  object_centres): where the object's orientation and extent are unknown, its middle is uncertain by about the
  class's footprint radius along the ray (`landmark_centre_sigma` radii). A wrong shift is a view-dependent bias
  (forward for objects ahead, less for objects beside), which the range would turn into a scale error of the map;
  the std weakens it but cannot remove a bias all views share (docs/api_example.py's straight drive with centres
  already at the middles: 2.2 % scale and 4 m of height without these stds, 0.7 % and 0.9 m at 2 radii);
- in height, `landmark_height_sigma`: object heights from stereo boxes are poor, and a landmark must not pull the
  map up or down.
A landmark so constrains the map mostly through its bearing in the ground plane, which the shift does not bias.
Observation factors carry a robust kernel: an object the map associated wrongly must not bend the map.

How the object map's life maps onto iSAM2, which only ever adds:
- only confirmed objects (seen `min_observations` times) become landmarks, so a tentative object the map forgets
  never enters the solver;
- the observation sums of an experience are added once the robot has left it (they are still growing while it is
  there); when it re-enters a stored experience and leaves again, the increment of each sum since it was added is a
  factor of its own (the sums are linear: what was added plus the increment is the new sum);
- a merge (two objects a correction brought together; the older id stays) adds no factor: the merged-away point
  keeps its factors, the object map re-files its sums to the kept object, and what was added of them counts as the
  kept one's, so that only views made since become the kept landmark's factors (a merge is decided on positions the
  map itself gives; as a tight factor it held true loops of KITTI 00 2-5 m open);
- a view of a landmark made more than `localised_distance` metres of travel ago is added only while the robot knows
  where it is (see `_trusted`): an association by a drifted pose is a guess, and a consistent wrong one is no outlier;
- a loop link withdrawn (neoslam.mapping.healing) has its factor removed from the solver, which iSAM2 allows;
- a map restored from a store or a join of two parts (a rigid move) rebuilds the solver from the graph: rare events.
Only the robot's part of the map is solved (a stored session not yet joined keeps its frame and its poses).
"""

from __future__ import annotations

from typing import Protocol

import gtsam
import numpy as np

from neoslam.config import ExperienceMapConfig, ObjectMapConfig
from neoslam.loop.keyframes import footprint_radii
from neoslam.mapping.graph import MapGraph
from neoslam.mapping.pose_graph import ANCHOR_SIGMA, OdometryNoise, link_noise_model, poses_from_values
from neoslam.types import ObjectMapState

__all__ = ["LOOP_ITERATIONS", "LandmarkSolver", "ObservationSource", "landmark_key"]

# iSAM2 relinearises a variable once its linearisation point is this far off (radians, metres): centimetre maps.
RELINEARIZE_THRESHOLD = 0.01
# An update is one Gauss-Newton step; a loop link can move the map by metres, so it gets this many more steps.
LOOP_ITERATIONS = 5
# A landmark nearer the experience's origin than this has no useful bearing (its views came from elsewhere in it).
MIN_RANGE_M = 1.0
# A ray this short in the ground plane (m) has no horizontal direction (a landmark straight above or below).
MIN_GROUND_RANGE_M = 1e-6
_UP = np.array([0.0, 0.0, 1.0])  # an experience's frame: x forward, y left, z up (REP-103)


class ObservationSource(Protocol):
    """What the solver reads from the object map (neoslam.mapping.object_map.ObjectMap)."""

    config: ObjectMapConfig
    merges: list[tuple[int, int]]
    footprints: dict[str, tuple[float, float]] | None  # class footprints the centres were shifted with, or None

    def state(self) -> ObjectMapState: ...


def landmark_key(object_id: int) -> int:
    """The Point3 key of an object: `l` + its id (experiences are keyed by their ids, far below)."""
    return gtsam.symbol("l", object_id)


class LandmarkSolver:
    """The robot's part of the experience map with the object landmarks, kept in one iSAM2."""

    def __init__(self, config: ExperienceMapConfig) -> None:
        self.config = config
        self._isam = _isam("CHOLESKY")
        self._factors = gtsam.NonlinearFactorGraph()  # every factor added, at its index in the solver
        self._loop_factors: dict[int, int] = {}  # loop link (index into graph.links) -> its factor's index
        self._removed: list[int] = []  # factors of withdrawn loop links, removed from the solver
        self._nodes = np.zeros(0, dtype=int)  # experiences in the solver, ascending
        self._links = 0  # graph.links added (the graph only appends links between rebuilds)
        self._merges = 0  # object-map merges followed
        self._landmarks: set[int] = set()
        self._added: dict[int, dict[int, np.ndarray]] = {}  # object -> experience -> [sums (3), weight, count] added
        self._estimate = gtsam.Values()
        self._first_seen: dict[int, float] = {}  # odometer reading when each landmark got its first factor, m
        self.odometer = 0.0  # the robot's odometer (m) and whether it knows where it is: set before an update
        self.localised = True
        self.odometry_noise: OdometryNoise | None = None  # per root second, for the links added next (link_sigmas)

    @property
    def nodes(self) -> np.ndarray:
        return self._nodes

    @property
    def landmarks(self) -> set[int]:
        return self._landmarks

    def update(
        self,
        graph: MapGraph,
        part: np.ndarray,
        source: ObservationSource,
        left: np.ndarray,
        current: int,
        iterations: int = 0,
    ) -> None:
        """Add what is new and correct graph.poses of the solved part in place: the part's new experiences (`part`, a
        mask over all), the links since the last update, the object map's merges, and the observation sums of the
        experiences in `left` (those the robot left since the last update) and of objects newly confirmed, never of
        the `current` experience (-1: all). `iterations`: more Gauss-Newton steps (after a loop link)."""
        factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        self._add_nodes(graph, part, factors, values)
        self._add_links(graph, factors)
        state = source.state()
        self._follow_merges(source)
        self._add_observations(source, state, left, current, factors, values)
        self._solve(graph, factors, values, [], iterations)

    def withdraw(self, links: list[int], graph: MapGraph) -> None:
        """Remove loop links' factors (indices into graph.links) and solve again, LOOP_ITERATIONS more steps: the
        map moves back by as much as the links had bent it; graph.poses of the part corrected in place."""
        factors = [self._loop_factors.pop(link) for link in links if link in self._loop_factors]
        if not factors:
            return  # none of them was added
        self._removed += factors
        self._solve(graph, gtsam.NonlinearFactorGraph(), gtsam.Values(), factors, LOOP_ITERATIONS)

    def _solve(self, graph: MapGraph, factors, values, remove: list[int], iterations: int) -> None:
        """One iSAM2 update with the new factors and values, less the factors `remove`, then `iterations` more
        steps; graph.poses of the part set from the solution."""
        self._factors.push_back(factors)
        try:
            self._isam.update(factors, values, remove)
        except RuntimeError:  # GTSAM's indeterminate linear system: see _isam
            self._isam = _isam("QR")
            values.insert(self._estimate)
            self._isam.update(self._factors, values)  # indices as before: the factors in the order added
            self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), self._removed)
        for _ in range(iterations):
            self._isam.update()
        self._estimate = self._isam.calculateEstimate()
        graph.poses[self._nodes] = poses_from_values(self._estimate, len(self._nodes))

    def landmark_position(self, object_id: int) -> np.ndarray:
        """The solved position of an object landmark (world frame of the part)."""
        return np.asarray(self._estimate.atPoint3(landmark_key(object_id)))

    def _add_nodes(self, graph: MapGraph, part: np.ndarray, factors, values) -> None:
        nodes = np.flatnonzero(part)
        new = nodes[~np.isin(nodes, self._nodes)]
        if len(new) == 0:
            return
        if len(self._nodes) == 0:  # the part's first experience fixes its frame
            anchor_noise = gtsam.noiseModel.Isotropic.Sigma(6, ANCHOR_SIGMA)
            factors.add(gtsam.PriorFactorPose3(int(new[0]), gtsam.Pose3(graph.poses[new[0]]), anchor_noise))
        for node in new:
            values.insert(int(node), gtsam.Pose3(graph.poses[node]))
        self._nodes = np.concatenate([self._nodes, new])
        self._nodes.sort()

    def _add_links(self, graph: MapGraph, factors) -> None:
        inside = set(self._nodes.tolist())
        withdrawn = set(graph.withdrawn)
        for index in range(self._links, len(graph.links)):
            link = graph.links[index]
            if index in withdrawn:
                continue
            if link.source in inside and link.target in inside:  # a link always ties one part: both or neither
                if link.kind == "loop":  # its factor's index in the solver once added
                    self._loop_factors[index] = self._factors.size() + factors.size()
                noise = link_noise_model(link, self.config, self.odometry_noise)
                factors.add(gtsam.BetweenFactorPose3(link.source, link.target, gtsam.Pose3(link.relative), noise))
        self._links = len(graph.links)

    def _follow_merges(self, source: ObservationSource) -> None:
        """Count what was added of a merged-away object's sums as the kept object's: the object map re-filed them
        there. No factor ties the two points: a merge is decided on positions the current map gives, not measured
        (a factor would feed the map's own estimate back into it; on KITTI 00 it held true loops 2-5 m open). Views
        associated with the kept object from then on tie its passes."""
        for gone, kept in source.merges[self._merges :]:
            into = self._added.setdefault(kept, {})
            for experience, added in self._added.pop(gone, {}).items():
                into[experience] = into.get(experience, 0.0) + added
        self._merges = len(source.merges)

    def _add_observations(
        self,
        source: ObservationSource,
        state: ObjectMapState,
        left: np.ndarray,
        current: int,
        factors,
        values,
    ) -> None:
        """A factor per observation sum (or its increment since added) of a confirmed object: those of the
        experiences left, and every sum of an object that is a landmark from now on."""
        objects = source.config
        counts = np.asarray(state.counts)
        confirmed = counts >= max(objects.min_observations, 1)
        landmarks = np.zeros(len(counts), dtype=bool)
        landmarks[list(self._landmarks)] = True
        fresh = np.flatnonzero(confirmed & ~landmarks)
        rows = np.isin(state.pair_experience, left) | np.isin(state.pair_object, fresh)
        rows &= confirmed[state.pair_object] & np.isin(state.pair_experience, self._nodes)
        rows &= state.pair_experience != current
        for row in np.flatnonzero(rows):
            obj, experience = int(state.pair_object[row]), int(state.pair_experience[row])
            total = np.concatenate([state.pair_sums[row], [state.pair_weights[row], state.pair_counts[row]]])
            added = self._added.setdefault(obj, {})
            increment = total - added.get(experience, 0.0)
            if increment[4] < 1:  # no view since the sum was added
                continue
            added[experience] = total
            if obj in self._landmarks and not self._trusted(obj):
                continue
            local = increment[:3] / increment[3]
            if obj not in self._landmarks:
                self._landmarks.add(obj)
                self._first_seen[obj] = self.odometer
                pose = self._pose(experience, values)
                values.insert(landmark_key(obj), pose.transformFrom(local))
            shift = footprint_radii([state.labels[obj]], _ground_bearing(local), source.footprints or {})[0]
            covariance = self._point_covariance(local, increment[3], increment[4], shift, objects)
            factors.add(self._observation_factor(obj, experience, local, covariance))

    def _trusted(self, obj: int) -> bool:
        """Whether a new view of a landmark may constrain the map: a landmark made within the last
        `localised_distance` metres of travel (the drift since is small), or any while the robot knows where it is (a
        place recognised within `localised_distance`). A robot back in known streets before a closure has
        recognised them associates its views by a drifted pose, and rows of parked cars give it a wrong neighbour as
        readily as the right one: consistent wrong associations outvote a robust kernel (on KITTI 00 they held 38
        true loop links 2-5 m open)."""
        return self.localised or self._first_seen[obj] >= self.odometer - self.config.localised_distance

    def _pose(self, experience: int, pending: gtsam.Values) -> gtsam.Pose3:
        return pending.atPose3(experience) if pending.exists(experience) else self._estimate.atPose3(experience)

    def _point_covariance(
        self, local: np.ndarray, weight: float, count: float, shift: float, objects: ObjectMapConfig
    ) -> np.ndarray:
        """Covariance of a sum's mean view `local` (experience frame), whose centre was shifted `shift` metres from
        the visible surface: independent stereo, centre-shift and height errors; see the module's note."""
        distance = max(float(np.linalg.norm(local)), MIN_RANGE_M)
        ray = local / distance
        ground = np.array([local[0], local[1], 0.0])
        ground_norm = float(np.linalg.norm(ground))
        along_ground = ground / ground_norm if ground_norm > MIN_GROUND_RANGE_M else ray
        depth = np.sqrt((count if self.config.landmark_noise == "per-view" else 1.0) / weight)
        floor = objects.position_sigma_floor
        stereo = depth**2 * np.outer(ray, ray) + floor**2 * (np.eye(3) - np.outer(ray, ray))
        middle = (self.config.landmark_centre_sigma * shift) ** 2 * np.outer(along_ground, along_ground)
        height = max(self.config.landmark_height_sigma**2 - floor**2, 0.0) * np.outer(_UP, _UP)
        return stereo + middle + height

    def _observation_factor(
        self, obj: int, experience: int, local: np.ndarray, covariance: np.ndarray
    ) -> gtsam.BearingRangeFactor3D:
        """The bearing-range factor of a sum's mean view `local` with its point covariance carried into the factor's
        error: GTSAM's Unit3 local coordinates (the bearing) are the tangent basis times the move across the ray over
        the range, the range error the move along the ray (linearised at the measurement)."""
        distance = float(np.linalg.norm(local))
        ray = local / max(distance, 1e-9)
        basis = np.asarray(gtsam.Unit3(ray).basis())
        jacobian = np.vstack([basis.T / max(distance, MIN_RANGE_M), ray[None]])
        noise = self._robust(gtsam.noiseModel.Gaussian.Covariance(jacobian @ covariance @ jacobian.T))
        return gtsam.BearingRangeFactor3D(experience, landmark_key(obj), gtsam.Unit3(ray), distance, noise)

    def _robust(self, gaussian: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
        kernel = self.config.landmark_robust_kernel
        threshold = self.config.landmark_robust_threshold
        if kernel == "huber":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(threshold), gaussian)
        if kernel == "cauchy":
            return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Cauchy.Create(threshold), gaussian)
        return gaussian


def _isam(factorization: str) -> gtsam.ISAM2:
    """An iSAM2 by Cholesky (fast) or QR: a frame that jumps far (motion limits at their largest: 8.6e7 m in a
    frame) makes a link's rotation Jacobian that large, and Cholesky of the squared system finds it indeterminate;
    QR solves it, at about twice the time on simulated KITTI 05, so a solver turns to QR only once Cholesky failed."""
    parameters = gtsam.ISAM2Params()
    parameters.setRelinearizeThreshold(RELINEARIZE_THRESHOLD)
    parameters.relinearizeSkip = 1  # every update: a landmark seen again after a loop moves at once
    parameters.setFactorization(factorization)
    return gtsam.ISAM2(parameters)


def _ground_bearing(local: np.ndarray) -> float:
    """Angle of a point (experience frame) off the experience's heading in the ground plane, radians."""
    return float(np.arctan2(local[1], local[0]))
