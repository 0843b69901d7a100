"""The map file: what goes in comes out exactly, commits write only what changed, every file that is not
a map this run may extend is refused with one line and left untouched, and a read-only map is never written."""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError, OutputError
from neoslam.store import map_file as map_file_module
from neoslam.store.map_file import MapFile
from neoslam.types import MapState, ObjectMapState

CONFIG = NeoSLAMConfig()


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def made(path: Path, growth, steps=(3, 9), config: NeoSLAMConfig = CONFIG) -> MapState:
    """A closed map at `path` after commits of the growth's states at `steps`; returns the last state."""
    with MapFile.create(path, config) as map_file:
        for step in steps:
            state = growth().state(step)
            map_file.commit(state)
    return state


def crashed_copy(path: Path, target: Path, growth, step: int = 12) -> MapState:
    """What a run killed after committing `step` leaves: the file and its write-ahead log (copied while open)."""
    made(path, growth, steps=(4,))
    with MapFile.open(path, CONFIG) as map_file:
        map_file.load()
        state = growth().state(step)
        map_file.commit(state)
        for suffix in ("", "-wal"):
            shutil.copyfile(f"{path}{suffix}", f"{target}{suffix}")
    assert Path(f"{target}-wal").stat().st_size > 0
    return state


# Round trip


def test_round_trip_holds_every_part_of_the_map_exactly(tmp_path, growth, same_state):
    from neoslam.cells.object_vector import ObjectVectorCells

    cells = ObjectVectorCells(CONFIG.object_vector)
    state = growth(patch=12, objects_per_keyframe=4).state(14)
    state.object_vector_weights = cells.weights()
    state.object_vector_losses = [0.9, 0.5, 0.25]
    assert {s.id for s in state.sessions} == {1, 2} and state.closures and state.objects.pair_object.size
    assert {link.kind for link in state.links} == {"odometry", "loop"} and state.hebbian
    assert np.any(state.objects.counts == 0)  # merged objects
    path = tmp_path / "map.neoslam"
    with MapFile.create(path, CONFIG) as map_file:
        map_file.commit(state)
    assert listing(tmp_path) == ["map.neoslam"]  # one self-contained file
    with MapFile.open(path, CONFIG) as map_file:
        loaded = map_file.load()
    same_state(loaded, state)
    assert {name: value.dtype for name, value in loaded.object_vector_weights.items()} == {
        name: value.dtype for name, value in state.object_vector_weights.items()
    }
    assert loaded.keyframes[0].patches.dtype == np.uint8 and loaded.keyframes[0].patches.shape == (4, 12, 12)
    assert any(k.provisional.any() for k in loaded.keyframes) and loaded.keyframes[0].provisional.dtype == bool
    np.testing.assert_array_equal(loaded.keyframes[3].distances, state.keyframes[3].distances)
    cells.restore(loaded.object_vector_weights, loaded.object_vector_losses)  # the OVCN takes them back
    # the file is SQLite any tool reads, with the format in its meta table
    with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as raw:
        meta = dict(raw.execute("SELECT key, value FROM meta"))
    assert meta["format"] == "neoslam-map" and meta["format_version"] == "5"
    assert json.loads(meta["config"]) == CONFIG.model_dump(mode="json")


def test_an_empty_map_loads_empty(tmp_path, same_state):
    path = tmp_path / "map.neoslam"
    MapFile.create(path, CONFIG).close()
    with MapFile.open(path, CONFIG) as map_file:
        same_state(map_file.load(), MapState())


def test_create_refuses_an_existing_path(tmp_path):
    path = tmp_path / "map.neoslam"
    path.write_text("mine")
    with pytest.raises(OutputError, match="exists already"):
        MapFile.create(path, CONFIG)
    assert path.read_text() == "mine" and listing(tmp_path) == ["map.neoslam"]
    with pytest.raises(OutputError, match="does not exist"):
        MapFile.create(tmp_path / "missing" / "map.neoslam", CONFIG)


# Incremental commits


class Statements:
    """The statements a connection runs, one per row of an executemany."""

    def __init__(self, map_file: MapFile) -> None:
        self.seen: list[str] = []
        map_file._connection.set_trace_callback(self.seen.append)

    def take(self) -> list[str]:
        seen = self.seen.copy()
        self.seen.clear()
        return [s for s in seen if s.split()[0] in ("INSERT", "UPDATE", "DELETE")]

    @staticmethod
    def on(statements: list[str], start: str) -> int:
        return sum(s.startswith(start) for s in statements)


def test_growing_commits_load_back_after_each(tmp_path, growth, same_state):
    path = tmp_path / "map.neoslam"
    grow = growth()
    with MapFile.create(path, CONFIG) as map_file:
        for step in [0, 1, 2, 3, 5, 6, 9, 10, 14, 15, 21]:
            state = grow.state(step)
            map_file.commit(state)
            same_state(map_file.load(), state)
    with MapFile.open(path, CONFIG) as map_file:
        same_state(map_file.load(), state)
        for step in (22, 26):  # a second session extends the map
            state = grow.state(step)
            map_file.commit(state)
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        same_state(map_file.load(), state)


def test_a_commit_writes_only_what_is_new_or_changed(tmp_path, growth):
    grow = growth(correction_every=1000)  # no correction: the stored poses never move
    path = tmp_path / "map.neoslam"
    map_file = MapFile.create(path, CONFIG)
    map_file.commit(grow.state(21))
    statements = Statements(map_file)
    map_file.commit(grow.state(21))
    assert statements.seen == []  # nothing changed: not even a transaction

    before, after = grow.state(21), grow.state(22)  # object 19 merges into 18
    map_file.commit(after)
    written = statements.take()
    assert Statements.on(written, "INSERT INTO keyframes") == 1
    new_experiences = len(after.experiences) - len(before.experiences)
    assert Statements.on(written, "INSERT INTO experiences") == new_experiences
    assert Statements.on(written, "INSERT INTO experience_poses") == 1  # the last block, which holds the new ones
    assert Statements.on(written, "INSERT INTO links") == len(after.links) - len(before.links)
    assert Statements.on(written, "INSERT INTO sessions") == 1  # its frame count grew
    changed_objects = (
        len(after.objects.labels)
        - len(before.objects.labels)
        + int(np.sum(np.any(after.objects.sums[: len(before.objects.labels)] != before.objects.sums, axis=1)))
    )
    assert Statements.on(written, "INSERT INTO objects") == changed_objects < len(after.objects.labels) // 2
    old = pairs(before.objects)
    new = pairs(after.objects)
    gone = old.keys() - new.keys()
    changed = [key for key, value in new.items() if old.get(key) != value]
    assert gone  # objects merged: their observation keys disappear
    assert Statements.on(written, "DELETE FROM object_observations") == len(gone)
    assert Statements.on(written, "INSERT INTO object_observations") == len(changed) < len(new) // 2
    assert Statements.on(written, "INSERT OR REPLACE INTO hebbian") == len(after.hebbian) - len(before.hebbian)
    assert Statements.on(written, "UPDATE") == 0

    # one corrected pose moves: one block of poses is rewritten, nothing else
    moved = grow.state(22)
    moved.experience_poses = moved.experience_poses.copy()
    moved.experience_poses[7, 0, 3] += 0.25
    map_file.commit(moved)
    written = statements.take()
    assert len(written) == 1 and written[0].startswith("INSERT INTO experience_poses")
    changes = map_file._connection.total_changes
    moved.experience_poses[40, 1, 3] -= 0.25  # in the second block
    moved.objects.weights = moved.objects.weights.copy()
    moved.objects.weights[2] += 1
    map_file.commit(moved)
    assert map_file._connection.total_changes - changes == 2  # one pose block, one object
    state = map_file.load()
    np.testing.assert_array_equal(state.experience_poses, moved.experience_poses)
    np.testing.assert_array_equal(state.objects.weights, moved.objects.weights)
    map_file.close()


def pairs(objects: ObjectMapState) -> dict[tuple[int, int], tuple]:
    return {
        (int(o), int(e)): (tuple(s), w, c)
        for o, e, s, w, c in zip(
            objects.pair_object,
            objects.pair_experience,
            objects.pair_sums,
            objects.pair_weights,
            objects.pair_counts,
            strict=True,
        )
    }


# Refusals: one line naming the problem, and the file (and anything beside it) exactly as it was


def refused(path: Path, problem: str, config: NeoSLAMConfig = CONFIG, read_only: bool = False) -> InputError:
    folder = path.parent
    before = {name: digest(folder / name) for name in listing(folder) if (folder / name).is_file()}
    with pytest.raises(InputError) as caught:
        MapFile.open(path, config, read_only=read_only)
    assert problem in caught.value.problem, caught.value.problem
    assert "\n" not in str(caught.value) and str(caught.value).startswith(str(path))
    after = {name: digest(folder / name) for name in listing(folder) if (folder / name).is_file()}
    assert after == before
    return caught.value


@pytest.mark.parametrize("read_only", [False, True])
def test_refuses_what_is_not_a_map(tmp_path, read_only):
    refused(tmp_path / "nothing.neoslam", "map not found", read_only=read_only)
    assert listing(tmp_path) == []
    (tmp_path / "folder").mkdir()
    refused(tmp_path / "folder", "a folder, not a NeoSLAM map file", read_only=read_only)
    (tmp_path / "empty.neoslam").write_bytes(b"")
    refused(tmp_path / "empty.neoslam", "empty file, not a NeoSLAM map", read_only=read_only)
    (tmp_path / "poses.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n")
    refused(tmp_path / "poses.txt", "not a SQLite file, so not a NeoSLAM map", read_only=read_only)
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as raw:
        raw.execute("CREATE TABLE places (name TEXT)")
    raw.close()
    refused(other, "a SQLite database but not a NeoSLAM map", read_only=read_only)
    with sqlite3.connect(other) as raw:
        raw.execute("CREATE TABLE meta (name TEXT, version INTEGER)")  # a `meta` of another kind
    raw.close()
    refused(other, "a SQLite database but not a NeoSLAM map", read_only=read_only)
    with sqlite3.connect(other) as raw:  # even with NeoSLAM's application id in its header
        raw.execute("PRAGMA application_id = 1314081869")
    raw.close()
    refused(other, "a SQLite database but not a NeoSLAM map", read_only=read_only)


def edited(path: Path, key: str, value: str) -> None:
    with sqlite3.connect(path) as raw:
        raw.execute("UPDATE meta SET value = ? WHERE key = ?", (value, key))
    raw.close()


@pytest.mark.parametrize("read_only", [False, True])
def test_refuses_another_format_version_or_neoslam_version(tmp_path, growth, read_only):
    path = tmp_path / "map.neoslam"
    made(path, growth)
    edited(path, "format_version", "4")  # before odometry links kept their duration
    refused(path, "map format version 4; this NeoSLAM reads version 5", read_only=read_only)
    edited(path, "format_version", "5")
    edited(path, "neoslam_version", "0.0.1")
    error = refused(path, "made by NeoSLAM 0.0.1; this is NeoSLAM ", read_only=read_only)
    assert map_file_module.__version__ in error.problem


def test_refuses_a_config_that_differs_in_a_map_section(tmp_path, growth):
    path = tmp_path / "map.neoslam"
    made(path, growth)
    relaxation = NeoSLAMConfig(experience_map={"backend": "relaxation"})
    error = refused(path, "", config=relaxation)
    assert error.problem == (
        "made with experience_map.backend = 'pose-graph'; this run has 'relaxation' "
        "(a map is extended with the config it was made with)"
    )
    error = refused(path, "", config=NeoSLAMConfig(matching={"min_inliers": 5}), read_only=True)
    assert error.problem.startswith("made with matching.min_inliers = 4; this run has 5 (")
    # sections a map does not depend on may differ
    other = NeoSLAMConfig(map_store={"synchronous": "normal"}, evaluation={"rpe_delta": 10.0})
    with MapFile.open(path, other) as map_file:
        map_file.load()


def test_refuses_a_truncated_or_corrupt_map(tmp_path, growth):
    path = tmp_path / "map.neoslam"
    made(path, growth, steps=(30,))
    whole = path.read_bytes()
    assert len(whole) > 20 * 4096
    path.write_bytes(whole[: len(whole) // 2])
    refused(path, "corrupt map file")
    refused(path, "corrupt map file", read_only=True)
    path.write_bytes(whole[:50])
    refused(path, "corrupt map file (truncated to 50 bytes)")
    damaged = bytearray(whole)
    damaged[4096 : 3 * 4096] = b"\xa5" * (2 * 4096)  # two pages of the schema's tables overwritten
    path.write_bytes(bytes(damaged))
    refused(path, "corrupt map file")
    path.write_bytes(whole)
    with sqlite3.connect(path) as raw:
        raw.execute("DROP TABLE hebbian")
    raw.close()
    refused(path, "corrupt map file (no table hebbian)")
    damaged = bytearray(whole)
    damaged[100:4096] = bytes(4096 - 100)  # the schema page zeroed
    path.write_bytes(bytes(damaged))
    refused(path, "corrupt map file")


def test_a_crashed_map_refused_keeps_its_log_untouched(tmp_path, growth):
    crashed = tmp_path / "crashed.neoslam"
    crashed_copy(tmp_path / "map.neoslam", crashed, growth)
    refused(crashed, "made with experience_map.backend", config=NeoSLAMConfig(experience_map={"backend": "relaxation"}))
    assert "crashed.neoslam-shm" not in listing(tmp_path)


def test_a_map_in_use_is_refused(tmp_path, growth):
    path = tmp_path / "map.neoslam"
    made(path, growth)
    with MapFile.open(path, CONFIG) as map_file:
        map_file.load()
        with pytest.raises(InputError, match="in use by another run"):
            MapFile.open(path, CONFIG)
    assert listing(tmp_path) == ["map.neoslam"]


# A map left by a killed run


@pytest.mark.parametrize("read_only", [False, True])
def test_a_crashed_map_opens_with_everything_committed(tmp_path, growth, same_state, read_only):
    crashed = tmp_path / "crashed.neoslam"
    state = crashed_copy(tmp_path / "map.neoslam", crashed, growth)
    digests = {name: digest(tmp_path / name) for name in ("crashed.neoslam", "crashed.neoslam-wal")}
    with MapFile.open(crashed, CONFIG, read_only=read_only) as map_file:
        same_state(map_file.load(), state)
    if read_only:  # read from a private copy: the map and its log stay as the crash left them
        assert {name: digest(tmp_path / name) for name in digests} == digests
        assert listing(tmp_path) == ["crashed.neoslam", "crashed.neoslam-wal", "map.neoslam"]
    else:  # recovered and folded into one file
        assert listing(tmp_path) == ["crashed.neoslam", "map.neoslam"]
        with MapFile.open(crashed, CONFIG, read_only=True) as map_file:
            same_state(map_file.load(), state)


# Read-only


def test_read_only_never_writes(tmp_path, growth, same_state):
    path = tmp_path / "map.neoslam"
    state = made(path, growth)
    before = digest(path)
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        assert listing(tmp_path) == ["map.neoslam"]
        same_state(map_file.load(), state)
        with pytest.raises(RuntimeError, match="read-only"):
            map_file.commit(growth().state(12))
    assert digest(path) == before and listing(tmp_path) == ["map.neoslam"]
    path.chmod(0o444)  # a map the user may only read
    try:
        with MapFile.open(path, CONFIG, read_only=True) as map_file:
            same_state(map_file.load(), state)
    finally:
        path.chmod(0o644)


def test_commit_needs_a_load_first_and_an_open_file(tmp_path, growth):
    path = tmp_path / "map.neoslam"
    made(path, growth)
    map_file = MapFile.open(path, CONFIG)
    with pytest.raises(RuntimeError, match="load"):
        map_file.commit(growth().state(12))
    map_file.close()
    map_file.close()  # twice is harmless
    with pytest.raises(RuntimeError, match="closed"):
        map_file.load()


def test_a_state_that_does_not_extend_the_map_is_refused_before_writing(tmp_path, growth, same_state):
    path = tmp_path / "map.neoslam"
    state = made(path, growth, steps=(9,))
    with MapFile.open(path, CONFIG) as map_file:
        map_file.load()
        with pytest.raises(ValueError, match="keyframes"):
            map_file.commit(growth().state(5))
        shuffled = growth().state(12)
        shuffled.experiences[20], shuffled.experiences[21] = shuffled.experiences[21], shuffled.experiences[20]
        with pytest.raises(ValueError, match="experience"):
            map_file.commit(shuffled)
        same_state(map_file.load(), state)


# Determinism


def test_the_same_commits_give_the_same_file(tmp_path, growth, same_state):
    for name in ("a.neoslam", "b.neoslam"):
        made(tmp_path / name, growth, steps=(2, 5, 9, 13))
        with MapFile.open(tmp_path / name, CONFIG) as map_file:
            map_file.load()
            map_file.commit(growth().state(17))
    with MapFile.open(tmp_path / "a.neoslam", CONFIG) as a, MapFile.open(tmp_path / "b.neoslam", CONFIG) as b:
        same_state(a.load(), b.load())
    assert digest(tmp_path / "a.neoslam") == digest(tmp_path / "b.neoslam")


def test_a_path_with_uri_characters_opens_read_only(tmp_path, growth, same_state):
    path = tmp_path / "map #1?mode=rw&x=%20.neoslam"
    state = made(path, growth)
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        same_state(map_file.load(), state)
    assert listing(tmp_path) == [path.name]
