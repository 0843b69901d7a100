"""Relocalisation in a stored map (beyond the paper; neoslam.store): a later session starts with no idea where it
is relative to the map, so its keyframes are matched against the whole stored map, not within a drift-bounded
radius. The verification is the loop-closure detector's own (the weighted fit, the evidence of one place against
every stored keyframe it could have matched, the place and level checks, another place as good making it
ambiguous, and consecutive keyframes that relocalise consistently), with `map_store.relocalisation_consecutive`
keyframes, no bound on the turn (the session's heading relative to the map is unknown too) and no drift prior (its
position is unknown). Candidates are the `map_store.relocalisation_candidates` places the retrieval ranks first
(`matching.retrieval`: object triangles by default).

Evidence that accumulates (`map_store.relocalisation_evidence: run`, the default): the whole map's threshold,
`matching.min_evidence_bits` plus log2 of the stored keyframes (13 bits for 160), is more than a keyframe that shares
four objects with the stored place carries, though the next keyframes see the same place. So a keyframe alone need
only show `min_evidence_bits`, and a run of consecutive keyframes that relocalise consistently (the detector's
consistency: one place for the robot, one heading) must show the whole map's threshold together:
- the run's best keyframe counts with its own evidence; every other keyframe adds the bits of the objects it matched
  that no keyframe before it counted (two pairs are one object when their stored objects, or their query objects,
  are of one label within `keyframes.association_radius`): consecutive keyframes see the same objects, and counting
  each keyframe's in full would count them again;
- a keyframe's fit spent bits fixing its three parameters, at most log2(object_area / (π consistent_distance²)) of
  them, since it had to land within `consistent_distance` of the run's, which chance does once in that many: they
  are taken from what its new objects add (a keyframe adds nothing, never less);
- every object a keyframe contradicts costs `matching.contradiction_bits` (`out_of_view_contradiction_bits` out of
  the place's view), once however many keyframes contradict it.
Runs are followed side by side (a keyframe may verify in several places), over at most
`map_store.relocalisation_run_keyframes` keyframes, and go on past `map_store.relocalisation_run_gap` keyframes that
relocalise nowhere (seeing too few objects shows nothing against a place); one that reaches the threshold at a
keyframe that relocalised in it is taken unless a run that puts
the robot elsewhere, in a place not joined to it, shows the whole map's threshold too and comes within
`matching.ambiguity_bits` of it; the closures of its
last `map_store.relocalisation_consecutive` keyframes are emitted. With `keyframe`, each of them must show the
whole map's threshold alone.

A session's frame is its first pose, tilted as the vehicle stood then, so two sessions' frames differ in roll and
pitch too, which the fit (in yaw and translation: objects' heights say little) cannot see. A closure here therefore
takes the robot's attitude at a place to be the stored robot's there, turned about its vertical by the fit's yaw
(the same road, the same vehicle): its relative pose is levelled, and joining the session to the map (see
ExperienceMap.join) brings the session's tilt into the map's frame from the two robots' attitudes."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from neoslam.config import KeyframeConfig, MapStoreConfig, MatchingConfig
from neoslam.geometry import yaw_of
from neoslam.loop.detector import LoopClosureDetector, _Relocalisation
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.matching import KeyframeMatch
from neoslam.types import Keyframe, LoopClosure

__all__ = ["MapRelocaliser", "WholeMapIndex"]


class WholeMapIndex(KeyframeIndex):
    """Stored keyframes, every one a candidate wherever the query is."""

    def eligible(self, position: np.ndarray, odometer_m: float) -> np.ndarray:
        return self._ids[: len(self.keyframes)].copy()

    def recent(self, keyframe_id: int, odometer_m: float) -> bool:
        return False  # a stored map's keyframes were made in another session


@dataclass(frozen=True)
class _Run:
    """Consecutive keyframes' relocalisations that agree on one place, and their evidence together (bits)."""

    steps: tuple[_Relocalisation, ...]
    bits: float


class MapRelocaliser(LoopClosureDetector):
    """Closures between a session's keyframes and a stored map's, searching the whole map."""

    def __init__(
        self, keyframes: KeyframeConfig, matching: MatchingConfig, store: MapStoreConfig, stored: Iterable[Keyframe]
    ) -> None:
        search = {"candidates": store.relocalisation_candidates, "consecutive": store.relocalisation_consecutive}
        super().__init__(keyframes, matching.model_copy(update=search))
        self.index = WholeMapIndex(self.config)
        for keyframe in stored:
            self.index.add(keyframe, 0.0)
        self.accumulate = store.relocalisation_evidence == "run"
        self.run_keyframes = store.relocalisation_run_keyframes
        self.run_gap = store.relocalisation_run_gap
        self._runs: list[_Run] = []  # the runs that can still go on
        # a later keyframe's fit must land within consistent_distance of the run's: what fixing it can spend
        disc = math.pi * self.config.consistent_distance**2
        self._later_spent_cap = max(math.log2(self.config.object_area / disc), 0.0)

    def __len__(self) -> int:
        return len(self.index)

    def _tested(self, eligible: int) -> int:
        return 1 if self.accumulate else eligible  # with runs, the whole map's share is asked of the run

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        if not self.accumulate:
            return super().query(keyframe, odometer_m)
        self._runs = self._extended(self._verified(keyframe, odometer_m), keyframe.id)
        here = [run for run in self._runs if run.steps[-1].keyframe_id == keyframe.id]
        best = max(here, key=lambda run: run.bits, default=None)
        self._recent.append(None if best is None else best.steps[-1])  # its place is tried first by the next one
        if best is None or not self._accepted(best):
            return []
        # the closures of the last `consecutive` keyframes, the ones a pipeline still holds the poses of
        steps = [step for step in best.steps if step.keyframe_id > keyframe.id - self.config.consecutive]
        for step in steps:
            self.joined.join(step.closure.query_keyframe, step.closure.match_keyframe)
        accepted = [step.closure for step in steps if step.keyframe_id not in self._emitted]
        self._emitted = {k for k in self._emitted if k > keyframe.id - self.config.consecutive}
        self._emitted.update(c.query_keyframe for c in accepted)
        return accepted

    def _extended(self, found: list[_Relocalisation], keyframe_id: int) -> list[_Run]:
        """The runs that can go on after this keyframe: each of its relocalisations after the run it agrees with
        that ended at most `run_gap` keyframes before (the one with the most evidence), or alone; and the runs
        that ended within the gap and none of them went on."""
        alive = [run for run in self._runs if run.steps[-1].keyframe_id >= keyframe_id - 1 - self.run_gap]
        runs, went_on = [], set()
        for step in found:
            longer = [
                (run, (*run.steps[max(len(run.steps) + 1 - self.run_keyframes, 0) :], step))
                for run in alive
                if self._consistent(run.steps[-1], step)
            ]
            scored = [(run, _Run(steps, self._run_bits(steps))) for run, steps in longer]
            before, extended = max(scored, key=lambda pair: pair[1].bits, default=(None, None))
            if extended is None:
                extended = _Run((step,), self._run_bits((step,)))
            else:
                went_on.add(id(before))
            runs.append(extended)
        return runs + [run for run in alive if id(run) not in went_on]

    def _accepted(self, run: _Run) -> bool:
        """Whether a run is long enough, shows the whole map's evidence, and no other run that shows it too, puts
        the robot elsewhere (in a place not joined to it) and comes within ambiguity_bits of it: as with keyframe
        evidence, where only keyframes that show the whole map's evidence verify."""
        needed = self.config.min_evidence_bits + math.log2(len(self.index))
        if len(run.steps) < self.config.consecutive or run.bits < needed:
            return False
        last = run.steps[-1]
        return not any(
            other is not run
            and other.bits >= needed
            and other.bits > run.bits - self.config.ambiguity_bits
            and not self._consistent(last, other.steps[-1])
            and not self.joined.same(last.members, other.steps[-1].members)
            for other in self._runs
        )

    def _run_bits(self, run: tuple[_Relocalisation, ...]) -> float:
        """A run's evidence (module docstring): its best keyframe's, then from every other keyframe the bits of the
        objects it matched that no keyframe before counted, less what its fit spent, and the cost of the objects it
        contradicted that none before did."""
        best = max(range(len(run)), key=lambda k: run[k].evidence)
        radius = self.places.association_radius
        matched = [pair[:3] for pair in _matched_pairs(run[best])]
        against = list(zip(run[best].match.contradicted_labels, run[best].match.contradicted, strict=True))
        bits = run[best].evidence
        for k, step in enumerate(run):
            if k == best:
                continue
            new = 0.0
            for label, stored, queried, pair_bits in sorted(_matched_pairs(step), key=lambda pair: -pair[3]):
                if not any(
                    label == other and (math.dist(stored, at) <= radius or math.dist(queried, seen) <= radius)
                    for other, at, seen in matched
                ):
                    matched.append((label, stored, queried))
                    new += pair_bits
            bits += max(new - min(step.match.spent_bits, self._later_spent_cap), 0.0)
            for label, at, seen in zip(
                step.match.contradicted_labels, step.match.contradicted, step.match.contradicted_in_view, strict=True
            ):
                if not any(label == other and math.dist(at, there) <= radius for other, there in against):
                    against.append((label, at))
                    bits -= self.config.contradiction_bits if seen else self.config.out_of_view_contradiction_bits
        return bits

    def _plausible_turn(self, match: KeyframeMatch, odometer_m: float) -> bool:
        return True  # the session's frame may be turned any way relative to the map's

    def _drift_bits(self, keyframe: Keyframe, transform: np.ndarray, stored: int, odometer_m: float) -> float:
        return 0.0  # the session's frame may lie anywhere in the map's: no prior on where the fit moves it

    def _closure(self, query: Keyframe, match: KeyframeMatch) -> tuple[LoopClosure, np.ndarray]:
        closure, offset = super()._closure(query, match)
        return replace(closure, relative_pose=_levelled(closure.relative_pose)), offset


def _matched_pairs(step: _Relocalisation) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """Each verified pair of a relocalisation: its label, the stored object's ground position (stored world), the
    query object's (query world) and the pair's bits."""
    query, place = step.sides
    return [
        (place.labels[j], place.centers[j, :2], query.centers[i, :2], float(bits))
        for (i, j), bits in zip(step.match.pairs.tolist(), step.match.pair_bits, strict=True)
    ]


def _levelled(relative: np.ndarray) -> np.ndarray:
    """A relative pose with its rotation reduced to the turn about the vertical."""
    yaw = float(yaw_of(relative))
    levelled = relative.copy()
    c, s = np.cos(yaw), np.sin(yaw)
    levelled[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    return levelled
