"""Loop-closure detection: retrieve candidates, match them, verify, pin the closure to the nearest place, and
accept only when consecutive keyframes relocalise consistently (a repeated pattern rarely repeats twice in a row
with the same offset; a revisited place does)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from neoslam.config import KeyframeConfig, MatchingConfig
from neoslam.geometry import invert_pose, rotation_angle, transform_points
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.matching import KeyframeMatch, match_keyframes
from neoslam.types import Keyframe, LoopClosure

__all__ = ["LoopClosureDetector"]

PASS_NEIGHBOURS = 3  # stored keyframes this close in id to a match belong to the same pass of a place


@dataclass(frozen=True)
class _Relocalisation:
    keyframe_id: int
    position: np.ndarray  # (3,) of the query keyframe's robot, query world
    transform: np.ndarray  # query world -> stored world
    closure: LoopClosure


class LoopClosureDetector:
    """Keeps the stored keyframes and answers, for each new keyframe, which loops it closes."""

    def __init__(self, keyframes: KeyframeConfig, matching: MatchingConfig) -> None:
        self.e_max = keyframes.e_max
        self.config = matching
        self.index = KeyframeIndex(matching)
        self._recent: deque[_Relocalisation | None] = deque(maxlen=max(matching.consecutive - 1, 0))
        self._emitted: set[int] = set()

    def _match(self, query: Keyframe, stored: int) -> KeyframeMatch:
        return match_keyframes(query, self.index.keyframes[stored], self.config, self.e_max)

    def _closure(self, query: Keyframe, match: KeyframeMatch) -> tuple[LoopClosure, np.ndarray]:
        """The closure and the offset (x, y, z) between the two robot poses implied by the fit."""
        stored = self.index.keyframes[match.match]
        relative = invert_pose(stored.pose) @ match.transform @ query.pose  # T_stored_query
        closure = LoopClosure(
            query_frame=query.frame_index,
            match_frame=stored.frame_index,
            query_keyframe=query.id,
            match_keyframe=stored.id,
            score=match.score,
            n_matches=match.n_matches,
            relative_pose=relative,
        )
        return closure, relative[:3, 3]

    def _ordered_candidates(self, keyframe: Keyframe, odometer_m: float, eligible: np.ndarray) -> list[int]:
        """Retrieval candidates; when the previous keyframe relocalised, first the stored keyframes next to its
        match: a place driven a third time then relocalises against one earlier pass, whose frame (and drift) the
        consistency test compares, rather than hopping between passes."""
        candidates = [int(c) for c in self.index.candidates(keyframe, odometer_m)]
        previous = self._recent[-1] if self._recent else None
        if previous is None or previous.keyframe_id != keyframe.id - 1:
            return candidates
        near = previous.closure.match_keyframe + np.arange(-PASS_NEIGHBOURS, PASS_NEIGHBOURS + 1)
        preferred = [int(c) for c in near if c in set(eligible.tolist())]
        return preferred + [c for c in candidates if c not in preferred]

    def relocalise(self, keyframe: Keyframe, odometer_m: float) -> _Relocalisation | None:
        """The first verified match among the retrieval candidates, moved to the stored keyframe nearest to the
        place the fit puts the robot (so it joins the same place, not a neighbour sharing the same objects)."""
        eligible = self.index.eligible(keyframe.pose[:3, 3], odometer_m)
        for candidate in self._ordered_candidates(keyframe, odometer_m, eligible):
            match = self._match(keyframe, int(candidate))
            if not match.verified:
                continue
            same_pass = eligible[np.abs(eligible - match.match) <= PASS_NEIGHBOURS]
            nearest = self.index.nearest((match.transform @ keyframe.pose)[:3, 3], same_pass)
            if nearest != match.match:
                match = self._match(keyframe, nearest)
                if not match.verified:
                    continue
            closure, offset = self._closure(keyframe, match)
            same_place = np.linalg.norm(offset[:2]) <= self.config.max_place_offset
            level = abs(offset[2]) <= self.config.max_vertical_offset
            if same_place and level and self._plausible_turn(match, odometer_m):
                return _Relocalisation(keyframe.id, keyframe.pose[:3, 3].copy(), match.transform, closure)
        return None

    def _plausible_turn(self, match: KeyframeMatch, odometer_m: float) -> bool:
        """Whether the fit's rotation is a heading drift the odometry can have built up since the stored keyframe
        (a nearly point-symmetric layout also fits turned by about 180°)."""
        travelled = odometer_m - self.index.odometer(match.match)
        bound = self.config.max_yaw_drift_deg + self.config.yaw_drift_per_100m * travelled / 100.0
        return bool(np.degrees(rotation_angle(match.transform[:3, :3])) <= bound)

    def _consistent(self, a: _Relocalisation, b: _Relocalisation) -> bool:
        """Whether two relocalisations put the robot at the same place: compared where the two keyframes were made,
        not at the world origin. The fits' yaw is only known to a few tenths of a degree, and after a few km of
        travel the world origin is that many km away: at the origin, a 0.3° difference alone moves the transform
        by metres, though both fits agree on the place to a few centimetres."""
        places = np.array([a.position, b.position])
        disagreement = np.linalg.norm(
            transform_points(a.transform, places) - transform_points(b.transform, places), axis=1
        )
        yaw_difference = rotation_angle(a.transform[:3, :3].T @ b.transform[:3, :3])
        return bool(
            disagreement.max() <= self.config.consistent_distance
            and np.degrees(yaw_difference) <= self.config.consistent_yaw_deg
        )

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        """Closures accepted with this keyframe: its own, and those of the preceding keyframes it confirms."""
        current = self.relocalise(keyframe, odometer_m)
        history = list(self._recent)
        self._recent.append(current)
        if current is None or any(h is None or not self._consistent(h, current) for h in history):
            return []
        if any(h.keyframe_id != keyframe.id - len(history) + i for i, h in enumerate(history)):
            return []  # not consecutive keyframes
        accepted = [h.closure for h in [*history, current] if h.keyframe_id not in self._emitted]
        # only the last `consecutive` keyframes can be emitted again: forget the others (a lifelong drive)
        self._emitted = {k for k in self._emitted if k > keyframe.id - len(history) - 1}
        self._emitted.update(c.query_keyframe for c in accepted)
        return accepted

    def add(self, keyframe: Keyframe, odometer_m: float) -> None:
        self.index.add(keyframe, odometer_m)

    def scores(self, keyframe: Keyframe) -> tuple[np.ndarray, np.ndarray]:
        """Spectral and verified matching scores of `keyframe` against every stored keyframe (paper Fig. 4c), with
        no retrieval and no gate."""
        matches = [self._match(keyframe, stored.id) for stored in self.index.keyframes]
        return np.array([m.score for m in matches]), np.array([m.verified_score for m in matches])
