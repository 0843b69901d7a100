"""Every value a map file holds is checked when it is opened: a map with a value that is not finite, a row that
names an id no row has, a BLOB of the wrong size, text that is not JSON, another format version in its header, a
file that is not a regular file or is too large to load, is refused with one line naming the table and the row, and
left byte for byte as it was. A session name that is not UTF-8 (a dataset folder's name) is kept exactly."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import sys
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError
from neoslam.store import validation
from neoslam.store.map_file import MapFile
from neoslam.types import SessionRecord

from .test_map_file import CONFIG, crashed_copy, digest, listing, made, refused

INF, NAN = float("inf"), float("nan")


def sql(*statements: str, values: tuple = ()) -> Callable[[Path], None]:
    def edit(path: Path) -> None:
        with closing(sqlite3.connect(path)) as raw:
            for statement in statements:
                raw.execute(statement, values if "?" in statement else ())
            raw.commit()

    return edit


def with_value(array: np.ndarray, index: tuple[int, ...], value: float) -> bytes:
    array = np.array(array, copy=True)
    array[index] = value
    return array.tobytes()


POSE_INF = with_value(np.eye(4), (0, 3), INF)
POSE_NAN = with_value(np.eye(4), (1, 3), NAN)

# name -> (the edit, what the refusal says)
CORRUPTIONS: dict[str, tuple[Callable[[Path], None], str]] = {
    "keyframe pose inf": (
        sql("UPDATE keyframes SET pose = ? WHERE id = 3", values=(POSE_INF,)),
        "table keyframes, row id 3: non-finite value inf in pose",
    ),
    "keyframe pose NaN": (
        sql("UPDATE keyframes SET pose = ? WHERE id = 3", values=(POSE_NAN,)),
        "table keyframes, row id 3: non-finite value NaN in pose",
    ),
    "keyframe centre": (
        sql("UPDATE keyframes SET centers = ? WHERE id = 1", values=(with_value(np.zeros((3, 3)), (2, 1), -INF),)),
        "table keyframes, row id 1: non-finite value -inf in centers",
    ),
    "keyframe covariance": (
        sql(
            "UPDATE keyframes SET covariances = ? WHERE id = 2",
            values=(with_value(np.zeros((3, 2, 2)), (0, 0, 0), NAN),),
        ),
        "table keyframes, row id 2: non-finite value NaN in covariances",
    ),
    "corrected pose": (
        sql("UPDATE experience_poses SET poses = ? WHERE block = 0", values=(np.full((19, 4, 4), NAN).tobytes(),)),
        "table experience_poses, row block 0: non-finite value NaN in poses",
    ),
    "odometry pose": (
        sql("UPDATE experiences SET odometry_pose = ? WHERE id = 5", values=(POSE_INF,)),
        "table experiences, row id 5: non-finite value inf in odometry_pose",
    ),
    "head direction": (
        sql("UPDATE experiences SET head_direction = 9e999 WHERE id = 4"),
        "table experiences, row id 4: non-finite value inf in head_direction",
    ),
    "link relative": (
        sql("UPDATE links SET relative = ? WHERE id = 2", values=(POSE_NAN,)),
        "table links, row id 2: non-finite value NaN in relative",
    ),
    "closure score": (
        sql("UPDATE closures SET score = -9e999 WHERE id = 0"),
        "table closures, row id 0: non-finite value -inf in score",
    ),
    "object sums": (
        sql("UPDATE objects SET sums = ? WHERE id = 2", values=(np.array([INF, 0.0, 0.0]).tobytes(),)),
        "table objects, row id 2: non-finite value inf in sums",
    ),
    "object weight": (
        sql("UPDATE objects SET weight = 9e999 WHERE id = 2"),
        "table objects, row id 2: non-finite value inf in weight",
    ),
    "observation weight text": (
        sql("UPDATE object_observations SET weight = 'nan' WHERE object = 0 AND experience = 0"),
        "table object_observations, row object 0, experience 0: weight is the text 'nan', not a number",
    ),
    "hebbian weights": (
        sql("UPDATE hebbian SET hd_weights = ? WHERE keyframe = 0", values=(np.full(5, NAN, "<f4").tobytes(),)),
        "table hebbian, row keyframe 0: non-finite value NaN in hd_weights",
    ),
    "OVCN weights": (
        sql("UPDATE object_vector SET data = ? WHERE position = 1", values=(np.full(32, INF, "<f4").tobytes(),)),
        "table object_vector, row position 1: non-finite value inf in data",
    ),
    "OVCN loss": (
        sql("UPDATE object_vector_losses SET loss = 9e999 WHERE epoch = 1"),
        "table object_vector_losses, row epoch 1: non-finite value inf in loss",
    ),
    "truncated blob": (
        sql("UPDATE keyframes SET centers = substr(centers, 1, 5) WHERE id = 2"),
        "table keyframes, row id 2: centers: a 5-byte value cannot hold a <f8 array of shape (3, 3)",
    ),
    "labels not JSON": (
        sql("UPDATE keyframes SET labels = 'car, bus' WHERE id = 2"),
        "table keyframes, row id 2: labels is not JSON",
    ),
    "labels nested deep": (
        sql("UPDATE keyframes SET labels = ? WHERE id = 2", values=("[" * 100_000,)),
        "table keyframes, row id 2: labels is not a flat JSON list",
    ),
    "text in an integer column": (
        sql("UPDATE keyframes SET objects = 'many' WHERE id = 2"),
        "table keyframes, row id 2: objects is the text 'many', not an integer",
    ),
    "link to a missing experience": (
        sql("UPDATE links SET target = 99999 WHERE id = 3"),
        "table links, row id 3: target is 99999, outside 0 .. 18",
    ),
    "link that spans negative time": (
        sql("UPDATE links SET duration_s = -0.5 WHERE id = 3"),
        "table links, row id 3: duration_s is -0.5: a link spans no negative time",
    ),
    "link whose duration is text": (
        sql("UPDATE links SET duration_s = 'long' WHERE id = 3"),
        "table links, row id 3: duration_s is the text 'long', not a number",
    ),
    "withdrawn link that is an odometry link": (
        sql("INSERT INTO withdrawn_links (link) VALUES (0)"),
        "table withdrawn_links, row link 0: names an odometry link: only loop links are withdrawn",
    ),
    "withdrawn link that is not in the map": (
        sql("INSERT INTO withdrawn_links (link) VALUES (9999)"),
        "table withdrawn_links, row link 9999: link is 9999, outside 0 .. 20",
    ),
    "observation of a missing object": (
        sql("UPDATE object_observations SET object = 999 WHERE object = 0 AND experience = 0"),
        "table object_observations, row object 999, experience 0: object is 999, outside 0 .. 8",
    ),
    "Hebbian trace of a missing keyframe": (
        sql("UPDATE hebbian SET keyframe = 500 WHERE keyframe = 0"),
        "table hebbian, row keyframe 500: keyframe 500 is not in table keyframes",
    ),
    "Hebbian cell outside the grid": (
        sql("UPDATE hebbian SET gc_indices = ? WHERE keyframe = 0", values=(np.full(27, 46_656, "<i4").tobytes(),)),
        "table hebbian, row keyframe 0: gc_indices holds a cell outside 0 .. 46655",
    ),
    "experience of a missing session": (
        sql("UPDATE experiences SET session = 7 WHERE id = 3"),
        "table experiences, row id 3: session 7 is not in table sessions",
    ),
    "keyframe of a missing experience": (
        sql("UPDATE keyframes SET experience = 4000 WHERE id = 1"),
        "table keyframes, row id 1: experience 4000 is not in table experiences",
    ),
    "OVCN parameter of another shape": (
        sql("UPDATE object_vector SET shape = '[1]' WHERE position = 0"),
        "table object_vector, row position 0: OVCN parameter 'hidden.weight' of shape [1]; the OVCN has shape [32, 3]",
    ),
    "OVCN parameter missing": (
        sql("DELETE FROM object_vector WHERE position = 3"),
        "table object_vector, row position 3: missing: OVCN parameter 'output.bias'",
    ),
    "more OVCN epochs than the config's": (
        sql(
            "WITH RECURSIVE n(x) AS (SELECT 3 UNION ALL SELECT x + 1 FROM n WHERE x < 500) "
            "INSERT INTO object_vector_losses SELECT x, 0.5 FROM n"
        ),
        "table object_vector_losses, row epoch 10: more epochs than the 10 the OVCN learns",
    ),
    "a table missing": (sql("DROP TABLE links"), "corrupt map file (no table links)"),
    "another format version in the header": (
        sql("PRAGMA user_version = 6"),
        "map format version 6 (a newer NeoSLAM's) in its header's user_version; this NeoSLAM reads version 5",
    ),
    "an older format version in the header": (
        sql("PRAGMA user_version = 4"),
        "map format version 4 in its header's user_version; this NeoSLAM reads version 5",
    ),
    "no user_version": (
        sql("PRAGMA user_version = 0"),
        "a SQLite database but not a NeoSLAM map (its header's user_version is 0; a map's is its format version, 5)",
    ),
}


@pytest.fixture(scope="module")
def whole_map(
    tmp_path_factory,
) -> Path:
    """A map of two sessions with every table filled (step 9: 19 experiences, 9 objects, 3 OVCN epochs)."""
    from .conftest import Growth

    path = tmp_path_factory.mktemp("whole") / "map.neoslam"
    made(path, lambda: Growth(), steps=(3, 9))
    return path


@pytest.mark.parametrize("read_only", [False, True], ids=["extend", "localise-only"])
@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_a_corrupt_value_is_refused_naming_table_and_row_and_the_file_is_left_as_it_was(
    whole_map, tmp_path, name, read_only
):
    edit, expected = CORRUPTIONS[name]
    path = tmp_path / "map.neoslam"
    shutil.copyfile(whole_map, path)
    edit(path)
    error = refused(path, expected, read_only=read_only)  # every file in the folder hashed before and after
    assert error.problem.count("\n") == 0 and listing(tmp_path) == ["map.neoslam"]


def test_a_crashed_map_with_a_corrupt_value_keeps_the_map_and_its_log_untouched(tmp_path, growth):
    crashed = tmp_path / "crashed.neoslam"
    crashed_copy(tmp_path / "made.neoslam", crashed, growth)
    edited = tmp_path / "edited.neoslam"
    with closing(sqlite3.connect(crashed)) as raw:  # a commit in the log, copied while it is there (as a crash)
        raw.execute("UPDATE objects SET weight = 9e999 WHERE id = 1")
        raw.commit()
        for suffix in ("", "-wal"):
            shutil.copyfile(f"{crashed}{suffix}", f"{edited}{suffix}")
    for leftover in ("made.neoslam", "crashed.neoslam"):
        (tmp_path / leftover).unlink()
    assert listing(tmp_path) == ["edited.neoslam", "edited.neoslam-wal"]
    refused(tmp_path / "edited.neoslam", "table objects, row id 1: non-finite value inf in weight")


def test_a_valid_map_loads_as_before_with_every_check(tmp_path, growth, same_state):
    path = tmp_path / "map.neoslam"
    state = made(path, growth, steps=(3, 9, 14))
    before = digest(path)
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        same_state(map_file.load(), state)
    assert digest(path) == before


# Files that are not regular files, and files too large to load


@contextmanager
def no_blocking(seconds: int = 5) -> Iterator[None]:
    """Fail instead of hanging when opening the file blocks (a FIFO opened for reading waits for a writer)."""

    def stop(signum, frame):
        raise AssertionError("opening the map blocked")

    previous = signal.signal(signal.SIGALRM, stop)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.mark.skipif(sys.platform == "win32", reason="FIFOs and devices are POSIX")
@pytest.mark.parametrize("read_only", [False, True])
def test_a_fifo_a_device_or_a_link_to_one_is_refused_without_blocking(tmp_path, read_only):
    fifo = tmp_path / "map.fifo"
    os.mkfifo(fifo)
    (tmp_path / "link.neoslam").symlink_to(fifo)
    (tmp_path / "device.neoslam").symlink_to("/dev/zero")
    with no_blocking():
        for path, kind in (
            (fifo, "a named pipe (FIFO)"),
            (tmp_path / "link.neoslam", "a named pipe (FIFO)"),
            (tmp_path / "device.neoslam", "a character device"),
            (Path("/dev/null"), "a character device"),
        ):
            with pytest.raises(InputError) as caught:
                MapFile.open(path, CONFIG, read_only=read_only)
            assert caught.value.problem == f"{kind}, not a regular file, so not a NeoSLAM map"
    assert sorted(listing(tmp_path)) == ["device.neoslam", "link.neoslam", "map.fifo"]


def test_a_map_larger_than_memory_is_refused_before_it_is_read(tmp_path, growth, monkeypatch):
    path = tmp_path / "map.neoslam"
    made(path, growth)
    size = path.stat().st_size
    try:
        os.truncate(path, 2**40)  # 1 TiB, sparse: SQLite reads only the pages its header counts
    except OSError:
        pytest.skip("this file system makes no sparse files")
    status = path.stat()
    with pytest.raises(InputError) as caught:
        MapFile.open(path, CONFIG)
    assert caught.value.problem.startswith("too large to load (1024.0 GiB; this machine has ")
    assert path.stat().st_mtime_ns == status.st_mtime_ns and listing(tmp_path) == ["map.neoslam"]
    os.truncate(path, size)
    pages = {"SC_PAGE_SIZE": 4096, "SC_PHYS_PAGES": 10}  # a machine of 40 kB
    monkeypatch.setattr(validation.os, "sysconf", lambda name: pages[name])
    refused(path, "too large to load (", read_only=True)


# Session names


def test_a_session_name_that_is_not_utf8_is_kept_exactly(tmp_path, growth, same_state):
    name = os.fsdecode(b"seq\xff \xe9t\xc3\xa9")  # a file name's bytes, not UTF-8 (but the last word)
    path = tmp_path / "map.neoslam"
    state = growth().state(8)
    state.sessions[1] = SessionRecord(2, name, state.sessions[1].frames, None)
    with MapFile.create(path, CONFIG) as map_file:
        map_file.commit(state)
    with closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as raw:
        stored = raw.execute("SELECT name FROM sessions ORDER BY id").fetchall()
    assert stored == [("first drive",), (b"seq\xff \xe9t\xc3\xa9",)]  # UTF-8 names stay text
    with MapFile.open(path, CONFIG) as map_file:
        same_state(map_file.load(), state)
        map_file.commit(state)  # the same name: nothing to write
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        assert map_file.load().sessions[1].name == name


def test_a_session_name_with_a_lone_surrogate_is_written(tmp_path, growth):
    state = growth().state(8)
    state.sessions[1] = SessionRecord(2, "odd \ud800 name", state.sessions[1].frames, None)
    path = tmp_path / "map.neoslam"
    with MapFile.create(path, CONFIG) as map_file:
        map_file.commit(state)
    with MapFile.open(path, CONFIG, read_only=True) as map_file:
        assert map_file.load().sessions[1].name.startswith("odd ")


@pytest.mark.slow
def test_a_dataset_folder_named_in_bytes_that_are_not_utf8_makes_and_extends_a_map(cli, tmp_path):
    ok = cli.ok
    plain = tmp_path / "plain"
    ok("simulate", "--route", "block", "--seed", "2", "--out", plain, "--quiet")
    data = plain.rename(tmp_path / os.fsdecode(b"seq\xff"))
    described = data / "dataset.yaml"  # the folder's name is the dataset's name when the file names none
    described.write_text(
        "".join(line for line in described.read_text().splitlines(True) if not line.startswith("name:"))
    )
    path = tmp_path / "map.db"
    ok("run", data, "--map", path, "--out", tmp_path / "a", "--quiet")
    ok("run", data, "--map", path, "--out", tmp_path / "b", "--quiet")
    with closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as raw:
        assert raw.execute("SELECT id, name FROM sessions").fetchall() == [(1, b"seq\xff"), (2, b"seq\xff")]
    metrics = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert metrics["session"]["id"] == 2
    with MapFile.open(path, NeoSLAMConfig(), read_only=True) as map_file:
        assert [s.name for s in map_file.load().sessions] == [data.name, data.name]
