"""Relocalisation in a stored map (beyond the paper; neoslam.store): a later session starts with no idea where it
is relative to the map, so its keyframes are matched against the whole stored map, not within a drift-bounded
radius. The verification is the loop-closure detector's own (the weighted fit, the evidence of one place against
every stored keyframe it could have matched, the place and level checks, another place as good making it
ambiguous, and consecutive keyframes that relocalise consistently), with `map_store.relocalisation_consecutive`
keyframes, no bound on the turn (the session's heading relative to the map is unknown too) and no drift prior (its
position is unknown). Candidates are the `map_store.relocalisation_candidates` places the retrieval ranks first
(`matching.retrieval`: object triangles by default).

Evidence that accumulates (`map_store.relocalisation_evidence: run`, the default; loop.runs): a keyframe alone need
only show `matching.min_evidence_bits`, and a run of consecutive keyframes that relocalise consistently must show the
whole map's threshold, `min_evidence_bits` plus log2 of the stored keyframes (13 bits for 160), together, over at most
`map_store.relocalisation_run_keyframes` keyframes and past `map_store.relocalisation_run_gap` keyframes that
relocalise nowhere; the closures of its last `map_store.relocalisation_consecutive` keyframes are emitted. With
`keyframe`, each of them must show the whole map's threshold alone.

A session's frame is its first pose, tilted as the vehicle stood then, so two sessions' frames differ in roll and
pitch too, which the fit (in yaw and translation: objects' heights say little) cannot see. A closure here therefore
takes the robot's attitude at a place to be the stored robot's there, turned about its vertical by the fit's yaw
(the same road, the same vehicle): its relative pose is levelled, and joining the session to the map (see
ExperienceMap.join) brings the session's tilt into the map's frame from the two robots' attitudes."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace

import numpy as np

from neoslam.config import KeyframeConfig, MapStoreConfig, MatchingConfig
from neoslam.geometry import yaw_of
from neoslam.loop.detector import LoopClosureDetector
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.matching import KeyframeMatch
from neoslam.types import Keyframe, LoopClosure

__all__ = ["MapRelocaliser", "WholeMapIndex"]


class WholeMapIndex(KeyframeIndex):
    """Stored keyframes, every one a candidate wherever the query is."""

    def eligible(self, position: np.ndarray, odometer_m: float) -> np.ndarray:
        return self._eligible_ids(np.arange(len(self.keyframes)))

    def recent(self, keyframe_id: int, odometer_m: float) -> bool:
        return False  # a stored map's keyframes were made in another session


class MapRelocaliser(LoopClosureDetector):
    """Closures between a session's keyframes and a stored map's, searching the whole map."""

    def __init__(
        self, keyframes: KeyframeConfig, matching: MatchingConfig, store: MapStoreConfig, stored: Iterable[Keyframe]
    ) -> None:
        search = {
            "candidates": store.relocalisation_candidates,
            "consecutive": store.relocalisation_consecutive,
            "evidence": store.relocalisation_evidence,
            "run_keyframes": store.relocalisation_run_keyframes,
            "run_gap": store.relocalisation_run_gap,
        }
        super().__init__(keyframes, matching.model_copy(update=search))
        self.index = WholeMapIndex(self.config)
        for keyframe in stored:
            self.index.add(keyframe, 0.0)

    def __len__(self) -> int:
        return len(self.index)

    def _plausible_turn(self, match: KeyframeMatch, odometer_m: float) -> bool:
        return True  # the session's frame may be turned any way relative to the map's

    def _drift_bits(self, keyframe: Keyframe, transform: np.ndarray, stored: int, odometer_m: float) -> float:
        return 0.0  # the session's frame may lie anywhere in the map's: no prior on where the fit moves it

    def _closure(self, query: Keyframe, match: KeyframeMatch) -> tuple[LoopClosure, np.ndarray]:
        closure, offset = super()._closure(query, match)
        return replace(closure, relative_pose=_levelled(closure.relative_pose)), offset


def _levelled(relative: np.ndarray) -> np.ndarray:
    """A relative pose with its rotation reduced to the turn about the vertical."""
    yaw = float(yaw_of(relative))
    levelled = relative.copy()
    c, s = np.cos(yaw), np.sin(yaw)
    levelled[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    return levelled
