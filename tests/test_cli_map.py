"""`neoslam run --map FILE`: a map kept in a file over sessions, through the CLI, with real map files.

Session A makes the map, session B (the same street driven again) relocalises in it and extends it, a
`--localise-only` session uses it and changes nothing; every refusal is one line, exit code 2, and leaves the file
as it was."""

from __future__ import annotations

import hashlib
import json
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.store.map_file import MapFile


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _metrics(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


def _tum_positions(path: Path) -> np.ndarray:
    return np.loadtxt(path)[:, 1:4]


@pytest.fixture(scope="module")
def street(cli, tmp_path_factory) -> Path:
    """The block route, simulated once (the street both sessions drive)."""
    folder = tmp_path_factory.mktemp("street") / "block"
    cli.ok("simulate", "--route", "block", "--noise", "vo", "--seed", "1", "--out", folder, "--quiet")
    return folder


@pytest.fixture(scope="module")
def first_session(cli, street: Path, tmp_path_factory) -> tuple[Path, Path]:
    """Session A: its map file and results folder."""
    folder = tmp_path_factory.mktemp("session_a")
    cli.ok("run", street, "--map", folder / "map.db", "--out", folder / "results", "--quiet")
    return folder / "map.db", folder / "results"


@pytest.fixture
def map_copy(first_session, tmp_path: Path) -> Path:
    copy = tmp_path / "map.db"
    copy.write_bytes(first_session[0].read_bytes())
    return copy


@pytest.mark.slow
def test_the_first_session_makes_a_map_in_its_own_frame(first_session):
    map_path, results = first_session
    session = _metrics(results)["session"]
    assert session["id"] == 1 and session["frame"] == "map" and session["map_keyframes"] == 0
    assert not Path(f"{map_path}-wal").exists(), "a closed map is one file"
    with closing(sqlite3.connect(map_path)) as connection:
        assert connection.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    stored = MapFile.open(map_path, NeoSLAMConfig(), read_only=True).load()
    assert len(stored.keyframes) == _metrics(results)["keyframes"] > 0
    assert len(stored.experiences) == _metrics(results)["experience_map"]["experiences"]
    assert {e.session for e in stored.experiences} == {1}


@pytest.mark.slow
def test_a_second_session_relocalises_in_the_map_and_extends_it(cli, street, first_session, map_copy, tmp_path):
    results_a = first_session[1]
    cli.ok("run", street, "--map", map_copy, "--out", tmp_path / "b", "--quiet")
    session = _metrics(tmp_path / "b")["session"]
    assert session["id"] == 2 and session["map_keyframes"] == _metrics(results_a)["keyframes"]
    assert session["relocalised_frame"] is not None and session["relocalised_frame"] < 100
    assert session["frame"] == "map" and session["map_closures"] > 0
    # In the map's frame: the same street driven again lies where session A put it.
    a = _tum_positions(results_a / "trajectory_tum.txt")
    b = _tum_positions(tmp_path / "b" / "trajectory_tum.txt")
    assert np.median(np.linalg.norm(a - b, axis=1)) < 1.0
    rows = (tmp_path / "b" / "loop_closures.csv").read_text().splitlines()
    assert rows[0].endswith(",session,match_session") and all(row.endswith(",2,1") for row in rows[1:])
    stored = MapFile.open(map_copy, NeoSLAMConfig(), read_only=True).load()
    assert [s.id for s in stored.sessions] == [1, 2]
    assert stored.sessions[1].relocalised_frame == session["relocalised_frame"]
    assert any(c.session == 2 and c.match_session == 1 for c in stored.closures)


@pytest.mark.slow
def test_localise_only_uses_the_map_and_changes_nothing_in_it(cli, street, map_copy, tmp_path):
    before = _digest(map_copy)
    cli.ok("run", street, "--map", map_copy, "--localise-only", "--out", tmp_path / "c", "--quiet")
    session = _metrics(tmp_path / "c")["session"]
    assert session["localise_only"] and session["relocalised_frame"] is not None
    assert _digest(map_copy) == before
    assert sorted(p.name for p in map_copy.parent.iterdir()) == ["c", "map.db"]


@pytest.mark.slow
def test_the_same_sessions_give_the_same_map(cli, street, first_session, tmp_path):
    cli.ok("run", street, "--map", tmp_path / "again.db", "--out", tmp_path / "a", "--quiet")
    assert _digest(tmp_path / "again.db") == _digest(first_session[0])


def test_localise_only_needs_a_map(cli, street, tmp_path):
    cli.one_line_error(
        cli.invoke("run", street, "--localise-only", "--out", tmp_path / "r"), "--localise-only needs --map"
    )
    result = cli.invoke("run", street, "--map", tmp_path / "none.db", "--localise-only", "--out", tmp_path / "r")
    cli.one_line_error(result, "none.db", "map not found")
    assert not (tmp_path / "none.db").exists() and not (tmp_path / "r").exists()


def test_a_run_that_fails_on_its_input_makes_no_map(cli, tmp_path):
    result = cli.invoke("run", tmp_path / "missing", "--map", tmp_path / "new.db", "--out", tmp_path / "r")
    cli.one_line_error(result, "missing")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["missing"] or not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "empty"),
        (b"frame,x,y\n1,2,3\n", "not a NeoSLAM map"),
        (b"\x89PNG\r\n\x1a\n" + bytes(200), "not a NeoSLAM map"),
    ],
    ids=["empty", "text", "png"],
)
def test_a_file_that_is_not_a_map_is_refused_and_left_alone(cli, street, tmp_path, content, expected):
    path = tmp_path / "map.db"
    path.write_bytes(content)
    line = cli.one_line_error(cli.invoke("run", street, "--map", path, "--out", tmp_path / "r"), "map.db")
    assert expected in line
    assert path.read_bytes() == content and not (tmp_path / "r").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.db"]


def test_a_sqlite_file_of_another_program_is_refused(cli, street, tmp_path):
    path = tmp_path / "other.db"
    with closing(sqlite3.connect(path)) as connection:
        connection.execute("CREATE TABLE notes (text TEXT)")
        connection.commit()
    before = _digest(path)
    cli.one_line_error(
        cli.invoke("run", street, "--map", path, "--out", tmp_path / "r"), "other.db", "not a NeoSLAM map"
    )
    assert _digest(path) == before


def test_a_truncated_map_is_refused_and_left_alone(cli, street, map_copy, tmp_path):
    map_copy.write_bytes(map_copy.read_bytes()[: map_copy.stat().st_size // 2])
    before = _digest(map_copy)
    cli.one_line_error(cli.invoke("run", street, "--map", map_copy, "--out", tmp_path / "r"), "map.db")
    assert _digest(map_copy) == before


def test_a_map_given_with_a_trigger_is_refused_before_it_could_run(cli, street, map_copy, tmp_path):
    """A map from elsewhere with a trigger that would delete keyframes at the run's first commit: one line, the map
    byte for byte as it was, no results."""
    with closing(sqlite3.connect(map_copy)) as connection:
        connection.execute("CREATE TRIGGER evil AFTER INSERT ON links BEGIN DELETE FROM keyframes WHERE id < 5; END")
        connection.commit()
    before = _digest(map_copy)
    result = cli.invoke("run", street, "--map", map_copy, "--out", tmp_path / "r")
    cli.one_line_error(result, "map.db", "a trigger 'evil' on table 'links' that the map format does not define")
    assert _digest(map_copy) == before and not (tmp_path / "r").exists()


def test_a_map_made_with_another_config_is_refused(cli, street, map_copy, tmp_path):
    config = tmp_path / "other.yaml"
    config.write_text("keyframes:\n  spacing: 7.5\n")
    before = _digest(map_copy)
    result = cli.invoke("run", street, "--map", map_copy, "--config", config, "--out", tmp_path / "r")
    cli.one_line_error(result, "map.db", "keyframes.spacing")
    assert _digest(map_copy) == before


def test_a_map_inside_the_results_folder_or_an_input_is_refused(cli, street, tmp_path):
    result = cli.invoke("run", street, "--map", tmp_path / "r" / "map.db", "--out", tmp_path / "r")
    cli.one_line_error(result, "results folder")
    cli.one_line_error(
        cli.invoke("run", street, "--map", street / "map.db", "--out", tmp_path / "r2"), "inside the input"
    )
    cli.one_line_error(cli.invoke("run", street, "--map", tmp_path, "--out", tmp_path / "r3"), "folder")
    assert not (street / "map.db").exists()


def _executable() -> str:
    beside = Path(sys.executable).parent / "neoslam"
    found = str(beside) if beside.is_file() else shutil.which("neoslam")
    assert found, "the neoslam console script is not installed"
    return found


@pytest.mark.slow
def test_a_run_killed_mid_way_leaves_a_map_a_later_session_relocalises_in(cli, street, first_session, tmp_path):
    """SIGKILL (no handler runs) once the run has committed: the map opens, passes SQLite's integrity check, holds
    a prefix of what the whole run stores, and a later session relocalises in it. (benchmarks/sessions.py kills
    20 runs at random moments.)"""
    path = tmp_path / "killed.db"
    command = [_executable(), "run", str(street), "--map", str(path), "--out", str(tmp_path / "r"), "--quiet"]
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wal = Path(f"{path}-wal")
    deadline = time.monotonic() + 60
    while not (wal.exists() and wal.stat().st_size > 100_000) and time.monotonic() < deadline:
        assert process.poll() is None, "the run ended before it was killed"
        time.sleep(0.05)
    process.send_signal(signal.SIGKILL)
    process.wait()
    with closing(sqlite3.connect(path)) as connection:
        assert connection.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    killed = MapFile.open(path, NeoSLAMConfig()).load()
    whole = MapFile.open(first_session[0], NeoSLAMConfig(), read_only=True).load()
    assert 0 < len(killed.keyframes) < len(whole.keyframes)
    for kept, complete in zip(killed.keyframes, whole.keyframes, strict=False):
        assert kept.id == complete.id and np.array_equal(kept.centers, complete.centers)
    assert not (tmp_path / "r").exists()
    cli.ok("run", street, "--map", path, "--out", tmp_path / "later", "--quiet")
    assert _metrics(tmp_path / "later")["session"]["relocalised_frame"] is not None
