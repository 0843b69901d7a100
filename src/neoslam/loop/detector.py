"""Loop-closure detection: retrieve candidates, match each as a place (loop.places) and verify, keep the match
with the most evidence unless another place verifies nearly as well (a repeated layout: then none), pin the closure
to the stored keyframe nearest to where the fit puts the robot, and accept only when consecutive keyframes
relocalise consistently (a repeated pattern rarely repeats twice in a row with the same offset; a revisited place
does).

Places that earlier closures joined are one place however far apart their odometry puts them (a street driven
three times verifies against both earlier passes): they never make a keyframe ambiguous."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from neoslam.config import KeyframeConfig, MatchingConfig
from neoslam.geometry import invert_pose, rotation_angle, transform_points
from neoslam.loop.index import KeyframeIndex
from neoslam.loop.matching import KeyframeMatch, MatchSide, match_keyframes, match_side
from neoslam.loop.places import Place, PlaceCache, merge_keyframes
from neoslam.loop.runs import EvidenceRuns, Relocalisation, Run
from neoslam.types import Keyframe, LoopClosure

__all__ = ["LoopClosureDetector"]

PASS_NEIGHBOURS = 3  # stored keyframes this close in id to a match belong to the same pass of a place
QUERY_HISTORY = 16  # keyframes kept for the query window (matching.query_radius: a few keyframe spacings)


class _JoinedPlaces:
    """Stored keyframes that accepted closures showed to be one place (union-find over keyframe ids)."""

    def __init__(self) -> None:
        self._parent: dict[int, int] = {}

    def find(self, keyframe_id: int) -> int:
        root = keyframe_id
        while self._parent.get(root, root) != root:
            root = self._parent[root]
        while keyframe_id != root:  # path compression
            self._parent[keyframe_id], keyframe_id = root, self._parent[keyframe_id]
        return root

    def join(self, a: int, b: int) -> None:
        self._parent[self.find(a)] = self.find(b)

    def same(self, a: tuple[int, ...], b: tuple[int, ...]) -> bool:
        """Whether two places share a keyframe or were joined."""
        return bool({self.find(k) for k in a} & {self.find(k) for k in b})


class LoopClosureDetector:
    """Keeps the stored keyframes and answers, for each new keyframe, which loops it closes."""

    def __init__(self, keyframes: KeyframeConfig, matching: MatchingConfig) -> None:
        self.e_max = keyframes.e_max
        self.config = matching
        self.index = KeyframeIndex(matching)
        self.places = PlaceCache(matching.place_radius, keyframes.association_radius, matching.place_cache)
        self.joined = _JoinedPlaces()
        self._recent: deque[Relocalisation | None] = deque(maxlen=max(matching.consecutive - 1, 0))
        self._queried: deque[Keyframe] = deque(maxlen=QUERY_HISTORY)  # the last keyframes queried
        self._emitted: set[int] = set()
        self._eligible = 0  # the stored keyframes the last query could have matched
        self.accumulate = matching.evidence == "run"
        self.runs = EvidenceRuns(
            matching, keyframes.association_radius, matching.run_keyframes, matching.run_gap, self._consistent
        )

    def _match(self, query: Keyframe | MatchSide, stored: Keyframe | MatchSide, tested: int = 1) -> KeyframeMatch:
        return match_keyframes(query, stored, self.config, self.e_max, self.index.label_shares(), tested)

    def _place(self, keyframe_id: int, odometer_m: float) -> Place:
        """The stored place of a candidate, without its recent members (`exclude_recent_distance`): their objects
        are the query's own street seen moments ago, and would agree with it whatever the place."""
        place = self.places.place(self.index.keyframes, self.index.slot(keyframe_id))
        kept = [m for m in place.members if not self.index.recent(m, odometer_m)]
        if len(kept) == len(place.members):
            return place
        keyframes = [self.index.keyframes[m] for m in kept]
        merged = merge_keyframes(keyframes, self.index.keyframes[keyframe_id], self.places.association_radius)
        return Place(merged, tuple(int(m) for m in kept))

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

    def _ordered_candidates(self, keyframe: Keyframe, eligible: np.ndarray) -> Iterator[tuple[int, np.ndarray | None]]:
        """Retrieval candidates, best first, with the triangle keys every stored keyframe (by slot) shares with the
        query (None: not known); when the previous keyframe relocalised, first the stored keyframes next to its
        match: a place driven a third time then relocalises against one earlier pass, whose frame (and drift) the
        consistency test compares, rather than hopping between passes."""
        previous = self._recent[-1] if self._recent else None
        preferred: list[int] = []
        if previous is not None and previous.keyframe_id == keyframe.id - 1:
            near = previous.closure.match_keyframe + np.arange(-PASS_NEIGHBOURS, PASS_NEIGHBOURS + 1)
            preferred = [int(c) for c in near[np.isin(near, eligible)]]
        ranked, shared = self.index.best_first(keyframe, eligible)
        for candidate in preferred:
            yield candidate, None
        for candidate in ranked:
            if candidate not in preferred:
                yield candidate, shared

    def relocalise(self, keyframe: Keyframe, odometer_m: float) -> Relocalisation | None:
        """The verified place match with the most evidence among the retrieval candidates (each tried once as a
        place), pinned to the member nearest to where the fit puts the robot; None when none verifies, or when
        another place, not joined to it, verifies with nearly as much evidence."""
        return self._unambiguous(self._verified(keyframe, odometer_m))

    def _tested(self, eligible: int) -> int:
        """The number of places a keyframe's evidence is weighed against (log2 of it is added to the bits needed):
        every eligible stored keyframe; with runs (`matching.evidence: run`), 1: the eligible keyframes' share is
        asked of the run."""
        return 1 if self.accumulate else eligible

    def _verified(self, keyframe: Keyframe, odometer_m: float) -> list[Relocalisation]:
        """Every retrieval candidate's place (each tried once) in which the keyframe relocalises."""
        eligible = self.index.eligible(keyframe.pose[:3, 3], odometer_m)
        self._eligible = len(eligible)
        query = self._query_window(keyframe)
        if not self._queried or self._queried[-1].id != keyframe.id:
            self._queried.append(keyframe)
        side = match_side(query, self.config)  # the query's share of matching, once for all its candidates
        found: list[Relocalisation] = []
        tried: set[int] = set()
        anchors: set[int] = set()  # the places tried again around where a failed fit put the robot
        places = 0
        for candidate, shared in self._ordered_candidates(query, eligible):
            if places == self.config.candidates:
                break
            if candidate in tried:
                continue
            place = self._place(candidate, odometer_m)
            tried.update(place.members)
            places += 1
            if shared is not None and max(shared[self.index.slot(m)] for m in place.members) < (
                self.config.min_shared_triangles
            ):
                continue  # not one of its triangles: it cannot hold the query's place
            relocalisation, match = self._relocalisation(side, place, eligible, odometer_m)
            anchor = None if relocalisation is not None else self._recentred(match, place, candidate, query)
            if anchor is not None and anchor not in anchors:
                anchors.add(anchor)
                place = self._place(anchor, odometer_m)
                tried.update(place.members)
                relocalisation, _ = self._relocalisation(side, place, eligible, odometer_m)
            if relocalisation is not None:
                found.append(relocalisation)
        return found

    def _recentred(self, match: KeyframeMatch | None, place: Place, anchor: int, query: Keyframe) -> int | None:
        """The member of a place nearest to where a fit puts the robot, when the fit failed on objects in view that
        the other side lacks (more than `max_contradictions`) and that member is not the place's anchor: the place
        around it holds the objects the query sees rather than the far end of the old place. None otherwise, or
        when `matching.recentre_places` is off."""
        if not self.config.recentre_places or match is None or match.contradicted_in_view is None:
            return None
        if np.count_nonzero(match.contradicted_in_view) <= self.config.max_contradictions:
            return None
        nearest = self.index.nearest((match.transform @ query.pose)[:3, 3], np.asarray(place.members))
        return None if nearest == anchor else nearest

    def _query_window(self, keyframe: Keyframe) -> Keyframe:
        """The keyframe with the keyframes queried just before it (ids one less each) whose robot poses lie within
        `query_radius` of its own, merged as a place is (loop.places). Those keyframes need not be stored: a
        keyframe recognised as a stored one is not stored again (lifelong mapping)."""
        members = [keyframe]
        for previous in reversed(self._queried):
            if previous.id == keyframe.id:
                continue  # queried before (relocalise, then query)
            if self.config.query_radius <= 0 or previous.id != members[-1].id - 1:
                break
            if np.linalg.norm(previous.pose[:2, 3] - keyframe.pose[:2, 3]) > self.config.query_radius:
                break
            members.append(previous)
        if len(members) == 1:
            return keyframe
        return merge_keyframes(members, keyframe, self.places.association_radius)

    def _relocalisation(
        self, query: MatchSide, place: Place, eligible: np.ndarray, odometer_m: float
    ) -> tuple[Relocalisation | None, KeyframeMatch | None]:
        """The query keyframe relocalised in one place, or None when the match fails verification or puts the robot
        too far from the place's keyframes, off its level, or turned more than the odometry can drift; `eligible`:
        the ids (increasing) of the stored keyframes it may close a loop with. With it, the match (None: no
        eligible member)."""
        keyframe = query.keyframe
        tested = self._tested(len(eligible))
        match = self._match(query, place.side(self.config), tested)
        members = np.asarray(place.members, dtype=int)
        found = np.minimum(np.searchsorted(eligible, members), max(len(eligible) - 1, 0))
        members = members[eligible[found] == members] if len(eligible) else members[:0]
        if not len(members):
            return None, None
        if not match.verified:
            return None, match
        nearest = self.index.nearest((match.transform @ keyframe.pose)[:3, 3], members)
        evidence = match.evidence + self._drift_bits(keyframe, match.transform, nearest, odometer_m)
        needed = self.config.min_evidence_bits + np.log2(max(tested, 1))
        if self.config.tolerances == "covariance" and evidence < needed:
            return None, match
        match = replace(match, match=nearest, evidence=evidence)
        closure, offset = self._closure(keyframe, match)
        same_place = np.linalg.norm(offset[:2]) <= self.config.max_place_offset
        level = abs(offset[2]) <= self.config.max_vertical_offset
        if not (same_place and level and self._plausible_turn(match, odometer_m)):
            return None, match
        position = keyframe.pose[:3, 3].copy()
        return Relocalisation(
            keyframe.id, position, match.transform, closure, match.evidence, place.members, match,
            (keyframe, place.keyframe),
        ), match  # fmt: skip

    def _unambiguous(self, found: list[Relocalisation]) -> Relocalisation | None:
        """The relocalisation with the most evidence (or the best in the pass the previous keyframe relocalised in),
        unless one that puts the robot elsewhere, in a place not joined to it, comes within `ambiguity_bits` of
        it."""
        if not found:
            return None
        found = sorted(found, key=lambda r: -r.evidence)
        best = found[0]
        previous = self._recent[-1] if self._recent else None
        if previous is not None and previous.keyframe_id == found[0].keyframe_id - 1:
            # the pass the previous keyframe relocalised in, when this one verifies there too: the consistency
            # test compares the two fits, and another pass of the same street has its own drift
            best = next((r for r in found if self._consistent(previous, r)), best)
        for other in found:
            if other is best or best.evidence - other.evidence >= self.config.ambiguity_bits:
                continue
            if not self._consistent(best, other) and not self.joined.same(best.members, other.members):
                return None
        return best

    def _drift_bits(self, keyframe: Keyframe, transform: np.ndarray, stored: int, odometer_m: float) -> float:
        """What a fit that moves the robot by d from where its odometry puts it costs, bits: the odometry's drift
        since the stored keyframe is taken as Gaussian with the drift radius R there (`drift_radius` plus
        `drift_radius_per_metre` of the metres travelled since) three standard deviations, -log2 of its density
        ratio to the centre, 4.5 (d / R)² / ln 2 (6.5 bits at R). With tolerances fixed: none."""
        if self.config.tolerances == "fixed":
            return 0.0
        travelled = odometer_m - self.index.odometer(stored)
        radius = self.config.drift_radius + self.config.drift_radius_per_metre * travelled
        position = keyframe.pose[:3, 3]
        moved = np.linalg.norm(transform_points(transform, position[None])[0, :2] - position[:2])
        return float(-4.5 * (moved / radius) ** 2 / np.log(2.0))

    def _plausible_turn(self, match: KeyframeMatch, odometer_m: float) -> bool:
        """Whether the fit's rotation is a heading drift the odometry can have built up since the stored keyframe
        (a nearly point-symmetric layout also fits turned by about 180°)."""
        travelled = odometer_m - self.index.odometer(match.match)
        bound = self.config.max_yaw_drift_deg + self.config.yaw_drift_per_100m * travelled / 100.0
        return bool(np.degrees(rotation_angle(match.transform[:3, :3])) <= bound)

    def _consistent(self, a: Relocalisation, b: Relocalisation) -> bool:
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

    # The steps of a query, one by one, for diagnostics (benchmarks sort the revisits a query missed by the first
    # step that loses them); the query itself calls the private ones.
    def query_window(self, keyframe: Keyframe) -> Keyframe:
        """The keyframe merged with the keyframes queried just before it, as a query matches it."""
        return self._query_window(keyframe)

    def ordered_candidates(self, keyframe: Keyframe, eligible: np.ndarray) -> Iterator[tuple[int, np.ndarray | None]]:
        """Retrieval candidates among the `eligible` stored keyframes (slots), best first, as a query tries them."""
        return self._ordered_candidates(keyframe, eligible)

    def place(self, keyframe_id: int, odometer_m: float) -> Place:
        """The stored place of a keyframe as a query at this odometer matches it."""
        return self._place(keyframe_id, odometer_m)

    def query(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        """Closures accepted with this keyframe: its own, and those of the preceding keyframes it confirms."""
        if self.accumulate:
            return self._query_runs(keyframe, odometer_m)
        current = self.relocalise(keyframe, odometer_m)
        history = list(self._recent)
        self._recent.append(current)
        if current is None or len(history) < (self._recent.maxlen or 0):
            return []  # the detector's first keyframes: not yet the consecutive ones a closure needs
        if any(h is None or not self._consistent(h, current) for h in history):
            return []
        if any(h.keyframe_id != keyframe.id - len(history) + i for i, h in enumerate(history)):
            return []  # not consecutive keyframes
        for h in [*history, current]:
            self.joined.join(h.closure.query_keyframe, h.closure.match_keyframe)
        accepted = [h.closure for h in [*history, current] if h.keyframe_id not in self._emitted]
        # only the last `consecutive` keyframes can be emitted again: forget the others (a lifelong drive)
        self._emitted = {k for k in self._emitted if k > keyframe.id - len(history) - 1}
        self._emitted.update(c.query_keyframe for c in accepted)
        return accepted

    def _query_runs(self, keyframe: Keyframe, odometer_m: float) -> list[LoopClosure]:
        """query with evidence that accumulates (loop.runs): the closures of the last `consecutive` keyframes of
        the run that reaches the eligible keyframes' threshold at this keyframe."""
        here = self.runs.extend(self._verified(keyframe, odometer_m), keyframe.id)
        needed = self.config.min_evidence_bits + np.log2(max(self._eligible, 1))
        taken = (run for run in here if self.runs.accepted(run, needed, self.config.consecutive, self._joined))
        best = next(taken, None)
        leading = best or (here[0] if here else None)
        self._recent.append(None if leading is None else leading.steps[-1])  # tried first by the next keyframe
        if best is None:
            return []
        # the closures of the last `consecutive` keyframes, the ones a pipeline still holds the poses of
        steps = [step for step in best.steps if step.keyframe_id > keyframe.id - self.config.consecutive]
        for step in steps:
            self.joined.join(step.closure.query_keyframe, step.closure.match_keyframe)
        accepted = [step.closure for step in steps if step.keyframe_id not in self._emitted]
        self._emitted = {k for k in self._emitted if k > keyframe.id - self.config.consecutive}
        self._emitted.update(c.query_keyframe for c in accepted)
        return accepted

    def _joined(self, a: Run, b: Run) -> bool:
        return self.joined.same(a.steps[-1].members, b.steps[-1].members)

    def add(self, keyframe: Keyframe, odometer_m: float) -> None:
        self.index.add(keyframe, odometer_m)

    def scores(self, keyframe: Keyframe) -> tuple[np.ndarray, np.ndarray]:
        """Spectral and verified matching scores of `keyframe` against every stored keyframe (paper Fig. 4c), with
        no retrieval and no gate."""
        matches = [self._match(keyframe, stored) for stored in self.index.keyframes]
        return np.array([m.score for m in matches]), np.array([m.verified_score for m in matches])
