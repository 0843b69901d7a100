"""Stored places: a stored keyframe with its neighbours of the same pass, matched as one.

A keyframe holds the objects around one point of the route. Two passes of a street through a real detector see
different subsets of its objects, and a pass driven the other way holds the objects on the other side of that point:
a revisit keyframe and the one stored nearest to it often share fewer objects than a match needs, though the
stored keyframes just before and after hold them. A place is the union of the stored keyframes whose robot poses
lie within `matching.place_radius` of the candidate's, following the stored order both ways from it while they do
(so one pass: a later pass of the same street lies elsewhere in the order). The keyframes of one pass share the
odometry frame, which is accurate over so short a stretch, so their objects are merged in place: objects of one
label within `keyframes.association_radius` are one, and the estimate with the smallest covariance (the most views)
stands for it. A query is merged the same way from the keyframes queried just before it (`matching.query_radius`:
the query window, loop.detector).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from neoslam.config import MatchingConfig
from neoslam.loop import kernels
from neoslam.loop.index import StoredKeyframes
from neoslam.loop.matching import MatchSide, match_side
from neoslam.types import Keyframe

__all__ = ["Place", "merge_keyframes", "PlaceCache"]


@dataclass(frozen=True)
class Place:
    """A candidate keyframe's place: the merged keyframe (the candidate's id and pose) and its members' ids."""

    keyframe: Keyframe
    members: tuple[int, ...]
    _side: list[MatchSide] = field(default_factory=list, compare=False, repr=False)

    def side(self, config: MatchingConfig) -> MatchSide:
        """The merged keyframe's share of matching (loop.matching.match_side), worked out when first asked for: a
        cached place is matched by many queries, always with its detector's config."""
        if not self._side:
            self._side.append(match_side(self.keyframe, config))
        return self._side[0]

    @property
    def nbytes(self) -> int:
        """Memory held by the merged keyframe and its share of matching once worked out, bytes."""
        return self.keyframe.nbytes + sum(side.nbytes for side in self._side)


def merge_keyframes(keyframes: list[Keyframe], anchor: Keyframe, association_radius: float) -> Keyframe:
    """One keyframe holding the objects of `keyframes` (one odometry frame), same-label objects within
    `association_radius` merged into the best-known of them; id and pose of `anchor`. A merged object is
    provisional only when every estimate of it is."""
    centers = np.concatenate([k.centers for k in keyframes])
    labels = [label for k in keyframes for label in k.labels]
    covariances = np.concatenate([k.covariances for k in keyframes])
    patches = np.concatenate([k.patches for k in keyframes])
    provisional = np.concatenate([k.provisional for k in keyframes])
    order = np.argsort(np.trace(covariances, axis1=1, axis2=2), kind="stable")  # the best-known first
    codes = np.concatenate(kernels.label_codes(*(k.labels for k in keyframes)))
    keep, provisional = kernels.kept_objects(kernels.plane(centers), codes, order, association_radius, provisional)
    return Keyframe(
        id=anchor.id,
        frame_index=anchor.frame_index,
        pose=anchor.pose,
        centers=centers[keep],
        labels=tuple(labels[i] for i in keep.tolist()),
        patches=patches[keep],
        provisional=provisional,
        covariances=covariances[keep],
        views=np.concatenate([k.views for k in keyframes]),
    )


def _distance(a: np.ndarray, b: np.ndarray) -> float:
    """|a - b|, the sums of np.linalg.norm without its per-call cost."""
    offset = a - b
    return math.sqrt(offset.dot(offset))


class PlaceCache:
    """The place of each stored keyframe, made when first asked for and kept once no later keyframe can join it
    (while the stored keyframes are the same collection: a detector given a new index starts afresh), at most
    `capacity` of them: the least recently asked for goes first."""

    def __init__(self, radius: float, association_radius: float, capacity: int = 1000) -> None:
        self.radius = radius
        self.association_radius = association_radius
        self.capacity = capacity
        self._places: OrderedDict[int, Place] = OrderedDict()
        self._of: StoredKeyframes | None = None

    def __len__(self) -> int:
        return len(self._places)

    @property
    def nbytes(self) -> int:
        """Memory held by the cached places, bytes."""
        return sum(place.nbytes for place in self._places.values())

    def place(self, stored: StoredKeyframes, slot: int) -> Place:
        """The place of the keyframe stored `slot`-th."""
        if stored is not self._of:
            self._places, self._of = OrderedDict(), stored
        anchor = stored.at(slot)
        cached = self._places.get(anchor.id)
        if cached is not None:
            self._places.move_to_end(anchor.id)
            return cached
        first = last = slot
        position = anchor.pose[:2, 3]
        while first > 0 and _distance(stored.at(first - 1).pose[:2, 3], position) <= self.radius:
            first -= 1
        while last + 1 < len(stored) and _distance(stored.at(last + 1).pose[:2, 3], position) <= self.radius:
            last += 1
        members = [stored.at(i) for i in range(first, last + 1)]
        merged = anchor if len(members) == 1 else merge_keyframes(members, anchor, self.association_radius)
        place = Place(merged, tuple(k.id for k in members))
        if last + 1 < len(stored):  # a keyframe beyond the place is stored: no later one can join it
            self._places[anchor.id] = place
            if len(self._places) > self.capacity:
                self._places.popitem(last=False)
        return place
