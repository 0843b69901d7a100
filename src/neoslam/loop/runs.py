"""Evidence that accumulates over consecutive keyframes (`matching.evidence: run` within a session,
`map_store.relocalisation_evidence: run` for a later session's relocaliser).

A place shows a keyframe only some of its objects: the threshold a match must carry, `matching.min_evidence_bits`
plus log2 of the stored keyframes it could have matched, is more than a keyframe that shares four objects with the
place carries, though the next keyframes see the same place. So a keyframe alone need only show
`min_evidence_bits`, and a run of consecutive keyframes that relocalise consistently (the detector's consistency:
one place for the robot, one heading) must show the full threshold together:
- the run's best keyframe counts with its own evidence; every other keyframe adds the bits of the objects it matched
  that no keyframe before it counted (two pairs are one object when their stored objects, or their query objects,
  are of one label within `keyframes.association_radius`): consecutive keyframes see the same objects, and counting
  each keyframe's in full would count them again;
- a keyframe's fit spent bits fixing its three parameters, at most log2(object_area / (π consistent_distance²)) of
  them, since it had to land within `consistent_distance` of the run's, which chance does once in that many: they
  are taken from what its new objects add (a keyframe adds nothing, never less);
- every object a keyframe contradicts costs `matching.contradiction_bits` (`out_of_view_contradiction_bits` out of
  the place's view), once however many keyframes contradict it.
Runs are followed side by side (a keyframe may verify in several places), over at most `run_keyframes` keyframes,
and go on past `run_gap` keyframes that relocalise nowhere (seeing too few objects shows nothing against a place);
the one with the most evidence that reaches the threshold at a keyframe that relocalised in it is taken (a run that
has just begun in another pass of the place may carry more and not be long enough yet) unless a run that puts the
robot elsewhere, in a place not joined to it, and that the keyframe relocalised in too, shows the threshold as well
and comes within `matching.ambiguity_bits` of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from neoslam.config import MatchingConfig
from neoslam.loop.matching import KeyframeMatch
from neoslam.types import Keyframe, LoopClosure

__all__ = ["Relocalisation", "Run", "EvidenceRuns"]


@dataclass(frozen=True)
class Relocalisation:
    """A query keyframe relocalised in one stored place."""

    keyframe_id: int
    position: np.ndarray  # (3,) of the query keyframe's robot, query world
    transform: np.ndarray  # query world -> stored world
    closure: LoopClosure
    evidence: float = 0.0  # bits (loop.verification.evidence_bits)
    members: tuple[int, ...] = ()  # the stored keyframes of the place matched
    match: KeyframeMatch | None = None  # the verified match: its pairs, their bits, the objects it contradicts
    sides: tuple[Keyframe, Keyframe] | None = None  # the query (window) and the place its pairs index


@dataclass(frozen=True)
class Run:
    """Consecutive keyframes' relocalisations that agree on one place, and their evidence together (bits)."""

    steps: tuple[Relocalisation, ...]
    bits: float


class EvidenceRuns:
    """The runs a detector follows; `consistent` tells whether two relocalisations put the robot at one place."""

    def __init__(
        self,
        config: MatchingConfig,
        association_radius: float,
        run_keyframes: int,
        run_gap: int,
        consistent: Callable[[Relocalisation, Relocalisation], bool],
    ) -> None:
        self.config = config
        self.association_radius = association_radius
        self.run_keyframes = run_keyframes
        self.run_gap = run_gap
        self.consistent = consistent
        self.runs: list[Run] = []  # the runs that can still go on
        # a later keyframe's fit must land within consistent_distance of the run's: what fixing it can spend
        disc = math.pi * config.consistent_distance**2
        self._later_spent_cap = max(math.log2(config.object_area / disc), 0.0)

    def extend(self, found: list[Relocalisation], keyframe_id: int) -> list[Run]:
        """Follow the runs past this keyframe's relocalisations; the runs that end at it, the most evidence first."""
        self.runs = self._extended(found, keyframe_id)
        here = [run for run in self.runs if run.steps[-1].keyframe_id == keyframe_id]
        return sorted(here, key=lambda run: -run.bits)

    def _extended(self, found: list[Relocalisation], keyframe_id: int) -> list[Run]:
        """The runs that can go on after this keyframe: each of its relocalisations after the run it agrees with
        that ended at most `run_gap` keyframes before (the one with the most evidence), or alone; and the runs
        that ended within the gap and none of them went on."""
        alive = [run for run in self.runs if run.steps[-1].keyframe_id >= keyframe_id - 1 - self.run_gap]
        runs, went_on = [], set()
        for step in found:
            longer = [
                (run, (*run.steps[max(len(run.steps) + 1 - self.run_keyframes, 0) :], step))
                for run in alive
                if self.consistent(run.steps[-1], step)
            ]
            scored = [(run, Run(steps, self.bits(steps))) for run, steps in longer]
            before, extended = max(scored, key=lambda pair: pair[1].bits, default=(None, None))
            if extended is None:
                extended = Run((step,), self.bits((step,)))
            else:
                went_on.add(id(before))
            runs.append(extended)
        return runs + [run for run in alive if id(run) not in went_on]

    def accepted(self, run: Run, needed: float, consecutive: int, joined: Callable[[Run, Run], bool]) -> bool:
        """Whether a run is `consecutive` keyframes long or more, shows the `needed` bits, and no other run that
        its last keyframe relocalised in too, that shows them as well, puts the robot elsewhere (in a place not
        `joined` to it) and comes within ambiguity_bits of it: as with keyframe evidence, where only keyframes that
        show the full threshold verify. (A run its keyframe did not go on is no other place for that keyframe.)"""
        if len(run.steps) < consecutive or run.bits < needed:
            return False
        last = run.steps[-1]
        return not any(
            other is not run
            and other.steps[-1].keyframe_id == last.keyframe_id
            and other.bits >= needed
            and other.bits > run.bits - self.config.ambiguity_bits
            and not self.consistent(last, other.steps[-1])
            and not joined(run, other)
            for other in self.runs
        )

    def bits(self, run: tuple[Relocalisation, ...]) -> float:
        """A run's evidence (module docstring): its best keyframe's, then from every other keyframe the bits of the
        objects it matched that no keyframe before counted, less what its fit spent, and the cost of the objects it
        contradicted that none before did."""
        best = max(range(len(run)), key=lambda k: run[k].evidence)
        radius = self.association_radius
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


def _matched_pairs(step: Relocalisation) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """Each verified pair of a relocalisation: its label, the stored object's ground position (stored world), the
    query object's (query world) and the pair's bits."""
    query, place = step.sides
    return [
        (place.labels[j], place.centers[j, :2], query.centers[i, :2], float(bits))
        for (i, j), bits in zip(step.match.pairs.tolist(), step.match.pair_bits, strict=True)
    ]
