"""Builders shared by the map-file tests: a map that grows step by step the way a run's does (deterministic, so a
state can be rebuilt from its step alone), and an exact comparison of two map states."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from functools import cache

import numpy as np
import pytest

from neoslam.types import (
    Experience,
    HebbianTrace,
    Keyframe,
    Link,
    LoopClosure,
    MapState,
    ObjectMapState,
    SessionRecord,
    StoredClosure,
)

LABELS = ("car", "truck", "person", "bicycle")


def _pose(rng: np.random.Generator) -> np.ndarray:
    pose = np.eye(4)
    angle = rng.uniform(-np.pi, np.pi)
    pose[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    pose[:3, 3] = rng.normal(0, 50, 3)
    return pose


@dataclass(frozen=True)
class Growth:
    """A map after `step` steps (one keyframe each): experiences, objects, observations and Hebbian traces grow
    with it, corrected poses change every third step, recent objects change for three steps, every odd object
    (from 3 on) merges into its neighbour three steps after it was made (its observation keys disappear), and
    keyframes before step 2 are associated late (like those made before the OVCN's first epoch)."""

    objects_per_keyframe: int = 3
    patch: int = 8
    experiences_per_step: float = 2.0
    objects_per_step: int = 1
    observations_per_object: int = 4
    gc_cells: int = 27
    hd_cells: int = 5
    second_session: int = 6  # the step from which the second session runs
    correction_every: int = 3  # steps between corrections that move every pose
    weights: tuple[tuple[str, tuple[int, ...]], ...] = (  # the OVCN's parameters (a map holds them all)
        ("hidden.weight", (32, 3)),
        ("hidden.bias", (32,)),
        ("output.weight", (1, 32)),
        ("output.bias", (1,)),
    )

    def experiences(self, step: int) -> int:
        return int(step * self.experiences_per_step) + 1

    def session(self, step_made: int) -> int:
        return 1 if step_made < self.second_session else 2

    @cache  # noqa: B019 (a few frozen instances live for the whole test session)
    def keyframe(self, index: int) -> Keyframe:
        rng = np.random.default_rng(index)
        n = self.objects_per_keyframe
        return Keyframe(
            id=index,
            frame_index=10 * index,
            pose=_pose(rng),
            centers=rng.normal(0, 20, (n, 3)),
            labels=tuple(LABELS[i % len(LABELS)] for i in rng.integers(0, len(LABELS), n)),
            patches=rng.integers(0, 256, (n, self.patch, self.patch), dtype=np.uint8),
            provisional=rng.random(n) < 0.3,
        )

    @cache  # noqa: B019
    def experience(self, index: int) -> tuple[Experience, np.ndarray]:
        rng = np.random.default_rng(10_000 + index)
        step = int(np.ceil(index / self.experiences_per_step))  # the step that made it
        while step > 0 and self.experiences(step - 1) > index:
            step -= 1
        while self.experiences(step) <= index:
            step += 1
        keyframe = step if index == self.experiences(step) - 1 and step > 0 else None
        experience = Experience(
            id=index,
            frame_index=3 * index,
            grid_cell=rng.uniform(0, 36, 3),
            head_direction=float(rng.uniform(0, 36)),
            pose=_pose(rng),
            linear_velocity=rng.normal(0, 5, 3),
            angular_velocity=rng.normal(0, 0.1, 3),
            keyframe_id=None if keyframe is None else keyframe - 1,
            session=self.session(step),
        )
        return experience, _pose(rng)

    @cache  # noqa: B019
    def trace(self, keyframe: int) -> HebbianTrace:
        rng = np.random.default_rng(20_000 + keyframe)

        def frozen(array: np.ndarray) -> np.ndarray:
            array.flags.writeable = False
            return array

        return HebbianTrace(
            frozen(np.sort(rng.choice(46_656, self.gc_cells, replace=False)).astype(np.int32)),
            frozen(rng.uniform(0, 1, self.gc_cells).astype(np.float32)),
            frozen(np.sort(rng.choice(36, self.hd_cells, replace=False)).astype(np.int32)),
            frozen(rng.uniform(0, 1, self.hd_cells).astype(np.float32)),
            (int(rng.integers(36)), int(rng.integers(36)), int(rng.integers(36))),
            int(rng.integers(36)),
            float(rng.uniform(0, 2)),
        )

    def state(self, step: int) -> MapState:
        """The map after `step` steps (0: empty but for one experience)."""
        n_exp = self.experiences(step)
        made = [self.experience(i) for i in range(n_exp)]
        experiences = [experience for experience, _ in made]
        offset = 1e-3 * (step // self.correction_every)  # a correction moves every pose
        poses = np.array([pose for _, pose in made]).reshape(n_exp, 4, 4) + offset
        keyframes = [self.keyframe(i) for i in range(step)]
        links = []  # in the order they are made: each experience's odometry link, every fifth a loop link too
        for i in range(1, n_exp):
            links.append(Link(i - 1, i, experiences[i].pose, "odometry", float(i) * 0.5))
            if i % 5 == 0:
                links.append(Link(i, i - 3, experiences[i - 1].pose, "loop", 0.0))
        closures = [
            StoredClosure(
                self.session(i),
                self.session(i - 4),
                LoopClosure(10 * i, 10 * i - 40, i, i - 4, 0.5 + i / 1000, 3 + i % 4, self.keyframe(i).pose),
            )
            for i in range(4, step, 5)
        ]
        sessions = [SessionRecord(1, "first drive", 10 * min(step, self.second_session), None)]
        if step >= self.second_session:  # from the step that made its first experience
            relocalised = 10 * (self.second_session + 2) if step > self.second_session + 2 else None
            sessions.append(SessionRecord(2, "second drive", 10 * (step - self.second_session), relocalised))
        hebbian = {i: self.trace(i) for i in range(step) if i % 4 != 3 and (i >= 2 or step >= 2)}
        epochs = min(step // 3, 10)
        weights = {}
        for position, (name, shape) in enumerate(self.weights):
            base = np.random.default_rng(30_000 + position).normal(0, 1, shape)
            weights[name] = (base * (1 + epochs)).astype(np.float32)
        return MapState(
            sessions=sessions,
            keyframes=keyframes,
            keyframe_experience={
                e.keyframe_id: e.id for e in experiences if e.keyframe_id is not None and e.keyframe_id < step
            },
            experiences=experiences,
            experience_poses=poses,
            links=links,
            # every second loop link was withdrawn again (a map that healed), in the order the links were made
            withdrawn_links=[i for i, link in enumerate(links) if link.kind == "loop" and link.source % 10 == 0],
            closures=closures,
            objects=self.objects(step),
            hebbian=hebbian,
            object_vector_weights=weights,
            object_vector_losses=[1.0 / (epoch + 1) for epoch in range(epochs)],
        )

    def objects(self, step: int) -> ObjectMapState:
        n = step * self.objects_per_step
        n_exp = self.experiences(step)
        ids = np.arange(n)
        made = ids // self.objects_per_step
        age = np.minimum(step - made, 3).astype(float)  # an object changes for three steps after it was made
        merged = (ids % 2 == 1) & (ids >= 3) & (step >= made + 3)
        owner = np.where(merged, ids - 1, ids)
        # raw observations: object o from the experiences of its step on
        raw_object = np.repeat(ids, self.observations_per_object)
        raw_experience = np.minimum((made * self.experiences_per_step).astype(int), n_exp - 1)
        raw_experience = np.repeat(raw_experience, self.observations_per_object) + np.tile(
            np.arange(self.observations_per_object), n
        )
        keep = raw_experience < n_exp
        raw_object, raw_experience = raw_object[keep], raw_experience[keep]
        raw_sums = (raw_object * 7.0 + raw_experience)[:, None] * np.array([1.0, 0.5, -0.25]) * age[raw_object, None]
        raw_weights = age[raw_object] * 0.5
        keys, inverse = np.unique(
            np.stack([owner[raw_object], raw_experience], axis=1).reshape(-1, 2), axis=0, return_inverse=True
        )
        inverse = inverse.ravel()
        pair_sums, pair_weights = np.zeros((len(keys), 3)), np.zeros(len(keys))
        pair_counts = np.zeros(len(keys), dtype=int)
        np.add.at(pair_sums, inverse, raw_sums)
        np.add.at(pair_weights, inverse, raw_weights)
        np.add.at(pair_counts, inverse, 1)
        sums, weights, counts = np.zeros((n, 3)), np.zeros(n), np.zeros(n, dtype=int)
        np.add.at(sums, owner[raw_object], raw_sums)
        np.add.at(weights, owner[raw_object], raw_weights)
        np.add.at(counts, owner[raw_object], 1)
        # the object map keeps its rows in the order they came, not sorted: shuffle them deterministically
        order = np.random.default_rng(step).permutation(len(keys))
        return ObjectMapState(
            labels=[LABELS[i % len(LABELS)] for i in range(n)],
            sums=sums,
            weights=weights,
            counts=counts,
            pair_object=keys[order, 0].copy(),
            pair_experience=keys[order, 1].copy(),
            pair_sums=pair_sums[order],
            pair_weights=pair_weights[order],
            pair_counts=pair_counts[order],
        )


def _same_arrays(a: np.ndarray, b: np.ndarray, where: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape, f"{where}: shape {a.shape} != {b.shape}"
    assert np.array_equal(a, b), f"{where}: values differ"


def _same_value(a, b, where: str) -> None:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        _same_arrays(a, b, where)
    elif isinstance(a, Keyframe | Experience | Link | LoopClosure | StoredClosure | HebbianTrace):
        assert type(a) is type(b), f"{where}: {type(a)} != {type(b)}"
        for f in fields(a):
            _same_value(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, list | tuple):
        assert len(a) == len(b), f"{where}: {len(a)} != {len(b)} items"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_value(x, y, f"{where}[{i}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for key in a:
            _same_value(a[key], b[key], f"{where}[{key!r}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _pairs_by_key(objects: ObjectMapState) -> tuple[np.ndarray, ...]:
    order = np.lexsort((np.asarray(objects.pair_experience), np.asarray(objects.pair_object)))
    return tuple(
        np.asarray(getattr(objects, name))[order]
        for name in ("pair_object", "pair_experience", "pair_sums", "pair_weights", "pair_counts")
    )


def assert_same_state(loaded: MapState, expected: MapState) -> None:
    """Every field equal, arrays exactly; observation rows compared by key (a map file returns them sorted)."""
    for f in fields(MapState):
        if f.name != "objects":
            _same_value(getattr(loaded, f.name), getattr(expected, f.name), f.name)
    a, b = loaded.objects, expected.objects
    assert list(a.labels) == list(b.labels), "objects.labels differ"
    for name in ("sums", "weights", "counts"):
        _same_arrays(getattr(a, name), getattr(b, name), f"objects.{name}")
    names = ("object", "experience", "sums", "weights", "counts")
    for x, y, name in zip(_pairs_by_key(a), _pairs_by_key(b), names, strict=True):
        _same_arrays(x, y, f"objects.pair_{name}")
    for trace in loaded.hebbian.values():
        assert not trace.gc_indices.flags.writeable and not trace.hd_weights.flags.writeable


@pytest.fixture
def growth() -> Callable[..., Growth]:
    return Growth


@pytest.fixture
def same_state() -> Callable[[MapState, MapState], None]:
    return assert_same_state
