"""Incremental commits (see neoslam.store.map_file): what a map state adds to, or changes in, what the map file
already holds, as the rows of the statements in schema.STATEMENTS.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from neoslam.store.schema import (
    F8,
    FLOAT_DTYPES,
    POSE_BLOCK,
    closure_row,
    encode,
    experience_row,
    hebbian_row,
    keyframe_row,
    link_row,
    session_row,
)
from neoslam.types import HebbianTrace, Keyframe, MapState, ObjectMapState, SessionRecord

__all__ = ["WrittenState"]


def _bits(values: np.ndarray) -> np.ndarray:
    """float64 values as their bit patterns: exact comparison (a NaN equals itself, -0.0 differs from 0.0)."""
    return values.view(np.uint64)


_NO_KEYS = np.zeros(0, dtype=np.int64)


@dataclass
class WrittenState:
    """What the file holds, as far as the next commit needs to know (copies, never the caller's arrays): counts of
    what only grows (keyframes, experiences, links, closures, OVCN epochs) and copies of what may change in place
    (corrected poses, objects and their observations, Hebbian traces, keyframes' experiences). `changes` compares a
    state with it (poses and object values bit for bit) and gives only the rows that differ, so that a commit at
    every keyframe writes what that keyframe added or changed, not the whole map."""

    sessions: dict[int, SessionRecord] = field(default_factory=dict)
    keyframes: int = 0
    last_keyframe: int = -1
    keyframe_experience: dict[int, int] = field(default_factory=dict)
    experiences: int = 0
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4)))
    links: int = 0
    withdrawn_links: int = 0
    closures: int = 0
    labels: list[str] = field(default_factory=list)
    object_sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    object_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    object_counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    pair_keys: np.ndarray = field(default_factory=lambda: _NO_KEYS)  # object << 32 | experience, sorted
    pair_sums: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pair_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    pair_counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    hebbian: dict[int, HebbianTrace] = field(default_factory=dict)
    losses: int = 0
    weights_written: bool = False

    @classmethod
    def of(cls, state: MapState) -> WrittenState:
        """The baseline of a state just loaded (so all of it is in the file)."""
        objects = state.objects
        pair_keys, pair_sums, pair_weights, pair_counts = _sorted_pairs(objects)
        return cls(
            sessions={record.id: record for record in state.sessions},
            keyframes=len(state.keyframes),
            last_keyframe=state.keyframes[-1].id if state.keyframes else -1,
            keyframe_experience=dict(state.keyframe_experience),
            experiences=len(state.experiences),
            poses=np.array(state.experience_poses, dtype=F8),
            links=len(state.links),
            withdrawn_links=len(state.withdrawn_links),
            closures=len(state.closures),
            labels=list(objects.labels),
            object_sums=np.array(objects.sums, dtype=F8).reshape(-1, 3),
            object_weights=np.array(objects.weights, dtype=F8),
            object_counts=np.array(objects.counts, dtype=np.int64),
            pair_keys=pair_keys,
            pair_sums=pair_sums,
            pair_weights=pair_weights,
            pair_counts=pair_counts,
            hebbian=dict(state.hebbian),
            losses=len(state.object_vector_losses),
            weights_written=bool(state.object_vector_weights),
        )

    def changes(self, state: MapState) -> tuple[list[tuple[str, list[tuple[Any, ...]]]], WrittenState]:
        """The statements (and their rows) that bring the file from this baseline to `state`, and the baseline
        after them. Raises ValueError, writing nothing, for a state that does not extend what was written."""
        new = WrittenState()
        operations: list[tuple[str, list[tuple[Any, ...]]]] = []

        def add(statement: str, rows: list[tuple[Any, ...]]) -> None:
            if rows:
                operations.append((statement, rows))

        new.sessions = {record.id: record for record in state.sessions}
        add("session", [session_row(r) for r in state.sessions if self.sessions.get(r.id) != r])
        add("keyframe", self._keyframes(state, new))
        add("keyframe_experience", self._keyframe_experiences(state, new))
        experience_rows, pose_blocks = self._experiences(state, new)
        add("experience", experience_rows)
        add("poses", pose_blocks)
        add("link", self._links(state, new))
        add("withdrawn_link", self._withdrawn_links(state, new))
        add("closure", self._closures(state, new))
        add("object", self._objects(state.objects, new))
        observation_rows, gone_rows = self._observations(state.objects, new)
        add("observation_gone", gone_rows)
        add("observation", observation_rows)
        hebbian_rows, hebbian_gone = self._hebbian(state, new)
        add("hebbian_gone", hebbian_gone)
        add("hebbian", hebbian_rows)
        for statement, rows in self._object_vector(state, new):
            add(statement, rows)
        return operations, new

    def _keyframes(self, state: MapState, new: WrittenState) -> list[tuple[Any, ...]]:
        keyframes = state.keyframes
        if len(keyframes) < self.keyframes:
            raise ValueError(f"the map holds {self.keyframes} keyframes; the state only {len(keyframes)}")
        if self.keyframes and keyframes[self.keyframes - 1].id != self.last_keyframe:
            raise ValueError(
                f"keyframe {self.keyframes - 1} of the state is not the one written (id {self.last_keyframe})"
            )
        rows = []
        last = self.last_keyframe
        for keyframe in keyframes[self.keyframes :]:
            if keyframe.id <= last:
                raise ValueError(f"keyframe ids must increase: {keyframe.id} after {last}")
            last = keyframe.id
            rows.append(keyframe_row(keyframe, state.keyframe_experience.get(keyframe.id)))
        new.keyframes, new.last_keyframe = len(keyframes), last
        return rows

    def _keyframe_experiences(self, state: MapState, new: WrittenState) -> list[tuple[Any, ...]]:
        """Experiences of keyframes written earlier that changed (a new keyframe's goes with its row)."""
        current, written = state.keyframe_experience, self.keyframe_experience
        new.keyframe_experience = dict(current)
        if current == written:
            return []
        fresh = {keyframe.id for keyframe in state.keyframes[self.keyframes :]}
        rows = []
        for keyframe_id in sorted(current.keys() | written.keys()):
            if keyframe_id in fresh or current.get(keyframe_id) == written.get(keyframe_id):
                continue
            if not (keyframe_id <= self.last_keyframe and _holds(state.keyframes[: self.keyframes], keyframe_id)):
                raise ValueError(f"keyframe_experience names keyframe {keyframe_id}, which the map does not hold")
            experience = current.get(keyframe_id)
            rows.append((None if experience is None else int(experience), int(keyframe_id)))
        return rows

    def _experiences(self, state: MapState, new: WrittenState) -> tuple[list, list]:
        """New experience rows, and the blocks of corrected poses that hold a new or changed pose."""
        experiences, old = state.experiences, self.experiences
        poses = np.array(state.experience_poses, dtype=F8)  # a copy: the next baseline
        if poses.shape != (len(experiences), 4, 4):
            raise ValueError(f"experience_poses has shape {poses.shape} for {len(experiences)} experiences")
        if len(experiences) < old:
            raise ValueError(f"the map holds {old} experiences; the state only {len(experiences)}")
        rows = []
        for index in range(old, len(experiences)):
            experience = experiences[index]
            if experience.id != index:
                raise ValueError(f"experience {index} of the state has id {experience.id}")
            rows.append(experience_row(experience))
        changed = (_bits(poses[:old]) != _bits(self.poses)).reshape(old, 16).any(axis=1)
        blocks = []
        if len(experiences) > old or changed.any():  # every block that holds a new or changed pose, whole
            touched = np.zeros(len(experiences), dtype=bool)
            touched[:old], touched[old:] = changed, True
            per_block = np.add.reduceat(touched, np.arange(0, len(experiences), POSE_BLOCK))
            for block in np.flatnonzero(per_block).tolist():
                start = block * POSE_BLOCK
                blocks.append((block, poses[start : start + POSE_BLOCK].tobytes()))
        new.experiences, new.poses = len(experiences), poses
        return rows, blocks

    def _links(self, state: MapState, new: WrittenState) -> list[tuple[Any, ...]]:
        if len(state.links) < self.links:
            raise ValueError(f"the map holds {self.links} links; the state only {len(state.links)}")
        new.links = len(state.links)
        return [link_row(index, link) for index, link in enumerate(state.links[self.links :], start=self.links)]

    def _withdrawn_links(self, state: MapState, new: WrittenState) -> list[tuple[Any, ...]]:
        """Loop links withdrawn since: the list only grows (a withdrawn link stays withdrawn)."""
        withdrawn = state.withdrawn_links
        if len(withdrawn) < self.withdrawn_links:
            raise ValueError(f"the map holds {self.withdrawn_links} withdrawn links; the state only {len(withdrawn)}")
        rows = []
        for index in withdrawn[self.withdrawn_links :]:
            if not (0 <= index < len(state.links) and state.links[index].kind == "loop"):
                raise ValueError(f"withdrawn link {index} is not a loop link of the map")
            rows.append((int(index),))
        new.withdrawn_links = len(withdrawn)
        return rows

    def _closures(self, state: MapState, new: WrittenState) -> list[tuple[Any, ...]]:
        if len(state.closures) < self.closures:
            raise ValueError(f"the map holds {self.closures} closures; the state only {len(state.closures)}")
        new.closures = len(state.closures)
        start = self.closures
        return [closure_row(index, stored) for index, stored in enumerate(state.closures[start:], start=start)]

    def _objects(self, objects: ObjectMapState, new: WrittenState) -> list[tuple[Any, ...]]:
        n, old = len(objects.labels), len(self.labels)
        sums = np.array(objects.sums, dtype=F8).reshape(-1, 3)
        weights = np.array(objects.weights, dtype=F8)
        counts = np.array(objects.counts, dtype=np.int64)
        if sums.shape != (n, 3) or weights.shape != (n,) or counts.shape != (n,):
            raise ValueError(f"object arrays of {len(sums)}, {len(weights)} and {len(counts)} rows for {n} labels")
        if n < old:
            raise ValueError(f"the map holds {old} objects; the state only {n}")
        changed = np.ones(n, dtype=bool)
        changed[:old] = (
            (_bits(sums[:old]) != _bits(self.object_sums)).any(axis=1)
            | (_bits(weights[:old]) != _bits(self.object_weights))
            | (counts[:old] != self.object_counts)
        )
        labels = list(objects.labels)
        if labels[:old] != self.labels:
            changed[:old] |= np.array([a != b for a, b in zip(labels[:old], self.labels, strict=True)])
        new.labels, new.object_sums, new.object_weights, new.object_counts = labels, sums, weights, counts
        indices = np.flatnonzero(changed)
        return [
            (index, labels[index], sums[index].tobytes(), weight, count)
            for index, weight, count in zip(
                indices.tolist(), weights[indices].tolist(), counts[indices].tolist(), strict=True
            )
        ]

    def _observations(self, objects: ObjectMapState, new: WrittenState) -> tuple[list, list]:
        """Observation rows new or changed (upserted) and keys that disappeared (deleted), compared by key."""
        keys, sums, weights, counts = _sorted_pairs(objects)
        p = len(keys)
        written = self.pair_keys
        at = np.minimum(np.searchsorted(written, keys), max(len(written) - 1, 0))
        known = written[at] == keys if len(written) else np.zeros(p, dtype=bool)
        changed = ~known
        old = at[known]
        changed[known] = (
            (_bits(sums[known]) != _bits(self.pair_sums[old])).any(axis=1)
            | (_bits(weights[known]) != _bits(self.pair_weights[old]))
            | (counts[known] != self.pair_counts[old])
        )
        kept = np.zeros(len(written), dtype=bool)
        kept[old] = True
        gone = written[~kept]
        new.pair_keys, new.pair_sums, new.pair_weights, new.pair_counts = keys, sums, weights, counts
        indices = np.flatnonzero(changed)
        upserts = [
            (key >> 32, key & 0xFFFFFFFF, sums[index].tobytes(), weight, count)
            for index, key, weight, count in zip(
                indices.tolist(),
                keys[indices].tolist(),
                weights[indices].tolist(),
                counts[indices].tolist(),
                strict=True,
            )
        ]
        return upserts, [(key >> 32, key & 0xFFFFFFFF) for key in gone.tolist()]

    def _hebbian(self, state: MapState, new: WrittenState) -> tuple[list, list]:
        rows = []
        for keyframe_id, trace in state.hebbian.items():
            stored = self.hebbian.get(keyframe_id)
            if stored is trace or (stored is not None and _same_trace(stored, trace)):
                continue
            rows.append(hebbian_row(keyframe_id, trace))
        gone = [(int(k),) for k in sorted(self.hebbian.keys() - state.hebbian.keys())]
        new.hebbian = dict(state.hebbian)
        rows.sort(key=lambda row: row[0])
        return rows, gone

    def _object_vector(self, state: MapState, new: WrittenState) -> list[tuple[str, list[tuple[Any, ...]]]]:
        losses, weights = state.object_vector_losses, state.object_vector_weights
        if len(losses) < self.losses:
            raise ValueError(f"the map holds {self.losses} OVCN epochs; the state only {len(losses)}")
        new.losses = len(losses)
        new.weights_written = self.weights_written or bool(weights)
        if len(losses) == self.losses and (self.weights_written or not weights):
            return []
        parameters = []
        for position, (name, value) in enumerate(weights.items()):
            array = np.asarray(value)
            dtype = array.dtype.newbyteorder("<").str
            if dtype not in FLOAT_DTYPES:
                raise ValueError(f"OVCN parameter {name} is {array.dtype}, not float32 or float64")
            parameters.append(
                (position, name, dtype, json.dumps(list(array.shape)), encode(array, FLOAT_DTYPES[dtype]))
            )
        epochs = [(epoch, float(loss)) for epoch, loss in enumerate(losses[self.losses :], start=self.losses)]
        return [("object_vector_cleared", [()]), ("object_vector", parameters), ("loss", epochs)]


def _sorted_pairs(objects: ObjectMapState) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The observation rows sorted by key, object << 32 | experience: keys, sums, weights, counts (copies)."""
    owners = np.asarray(objects.pair_object, dtype=np.int64)
    anchors = np.asarray(objects.pair_experience, dtype=np.int64)
    p = len(owners)
    if anchors.shape != (p,):
        raise ValueError(f"{len(anchors)} observation experiences for {p} objects")
    if p and (owners.min() < 0 or owners.max() >= 2**31 or anchors.min() < 0 or anchors.max() >= 2**31):
        raise ValueError("observation object and experience ids must lie in 0 .. 2^31 - 1")
    keys = (owners << 32) | anchors
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    if np.any(keys[1:] == keys[:-1]):
        raise ValueError("the object map holds two observation rows of one (object, experience)")
    sums = np.asarray(objects.pair_sums, dtype=F8).reshape(-1, 3)
    weights = np.asarray(objects.pair_weights, dtype=F8)
    counts = np.asarray(objects.pair_counts, dtype=np.int64)
    if sums.shape != (p, 3) or weights.shape != (p,) or counts.shape != (p,):
        raise ValueError(f"observation arrays of {len(sums)}, {len(weights)} and {len(counts)} rows for {p} keys")
    return keys, sums[order], weights[order], counts[order]  # fancy indexing: copies


def _holds(keyframes: list[Keyframe], keyframe_id: int) -> bool:
    """Whether a keyframe of that id is among `keyframes` (sorted by id)."""
    low, high = 0, len(keyframes)
    while low < high:
        middle = (low + high) // 2
        if keyframes[middle].id < keyframe_id:
            low = middle + 1
        else:
            high = middle
    return low < len(keyframes) and keyframes[low].id == keyframe_id


def _same_trace(a: HebbianTrace, b: HebbianTrace) -> bool:
    return (
        tuple(a.gc_peak) == tuple(b.gc_peak)
        and a.hd_peak == b.hd_peak
        and a.strength == b.strength
        and all(
            np.array_equal(x, y)
            for x, y in (
                (a.gc_indices, b.gc_indices),
                (a.gc_weights, b.gc_weights),
                (a.hd_indices, b.hd_indices),
                (a.hd_weights, b.hd_weights),
            )
        )
    )
