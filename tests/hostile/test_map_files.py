"""A map file is untrusted input: a map given with triggers, views, indexes, extra tables or tables rebuilt with other
columns is refused with one line before anything is written, and left byte for byte as it was; SQLite's complaints
about a damaged file or a foreign log are one line; a statement that runs long stops on Ctrl-C; a full disk under a
run's map is one line, the map whole up to its last commit. Maps are written by the tests themselves (the store's
Growth: a two-session map with every table filled)."""

from __future__ import annotations

import hashlib
import os
import signal
import sqlite3
import subprocess
import threading
import time
from pathlib import Path

import pytest
from tests.store.conftest import Growth

from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError, OutputError
from neoslam.store.map_file import MapFile
from neoslam.store.validation import interrupted

CONFIG = NeoSLAMConfig()
MESSAGE_CHARS = 400  # one line a user reads, not SQLite's complaint about every page
GIVE_UP_S = 5.0  # a statement Ctrl-C did not stop is interrupted after this


def _made(path: Path, steps: tuple[int, ...] = (3, 9)) -> Path:
    with MapFile.create(path, CONFIG) as map_file:
        for step in steps:
            map_file.commit(Growth().state(step))
    return path


@pytest.fixture(scope="module")
def stored(tmp_path_factory) -> bytes:
    """The bytes of a closed two-session map."""
    return _made(tmp_path_factory.mktemp("stored") / "map.neoslam").read_bytes()


def _digests(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def _refused(path: Path, *parts: str, read_only: bool = False) -> str:
    """MapFile.open refuses the map with one line naming every part, and nothing beside it changes."""
    before = _digests(path.parent)
    with pytest.raises(InputError) as caught:
        MapFile.open(path, CONFIG, read_only=read_only)
    line = str(caught.value)
    assert "\n" not in line and len(line) < MESSAGE_CHARS + len(str(path)), line
    for part in parts:
        assert part in line, (part, line)
    assert _digests(path.parent) == before
    return line


def _edited(path: Path, *statements: str) -> None:
    raw = sqlite3.connect(path)
    try:
        for statement in statements:
            raw.execute(statement)
        raw.commit()
    finally:
        raw.close()


EVIL = {
    "a trigger that deletes keyframes when a link is written": (
        "CREATE TRIGGER evil AFTER INSERT ON links BEGIN DELETE FROM keyframes WHERE id < 5; "
        "INSERT INTO meta VALUES ('evil', 'yes'); END",
        ("a trigger 'evil' on table 'links' that the map format does not define",),
    ),
    "a trigger that runs for ever": (
        "CREATE TRIGGER spin AFTER UPDATE ON sessions BEGIN SELECT count(*) FROM (WITH RECURSIVE n(x) AS "
        "(SELECT 1 UNION ALL SELECT x + 1 FROM n) SELECT x FROM n); END",
        ("a trigger 'spin' on table 'sessions'",),
    ),
    "a trigger that aborts every write": (
        "CREATE TRIGGER nope BEFORE INSERT ON experiences BEGIN SELECT RAISE(ABORT, 'no'); END",
        ("a trigger 'nope' on table 'experiences'",),
    ),
    "a unique index the format does not have": (
        "CREATE UNIQUE INDEX one_name ON sessions(name)",
        ("an index 'one_name' on table 'sessions'",),
    ),
    "a view": ("CREATE VIEW everything AS SELECT * FROM keyframes", ("a view 'everything'",)),
    "an extra table": ("CREATE TABLE notes (text TEXT)", ("a table 'notes' that the map format does not define",)),
}
EVIL_IDS = list(EVIL)


@pytest.mark.parametrize("read_only", [False, True], ids=["extend", "localise-only"])
@pytest.mark.parametrize("case", EVIL_IDS)
def test_a_map_with_schema_objects_the_format_does_not_define_is_refused_untouched(tmp_path, stored, case, read_only):
    statement, parts = EVIL[case]
    path = tmp_path / "map.neoslam"
    path.write_bytes(stored)
    _edited(path, statement)
    _refused(path, *parts, read_only=read_only)


REBUILT = {
    "columns in another order, the rows copied by name": (
        "CREATE TABLE links_new (id INTEGER PRIMARY KEY, target INTEGER NOT NULL, source INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('odometry', 'loop')), distance_m REAL NOT NULL, "
        "duration_s REAL NOT NULL)",
        "INSERT INTO links_new (id, target, source, relative, kind, distance_m, duration_s) "
        "SELECT id, target, source, relative, kind, distance_m, duration_s FROM links",
    ),
    "a column dropped": (
        "CREATE TABLE links_new (id INTEGER PRIMARY KEY, source INTEGER NOT NULL, target INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('odometry', 'loop')))",
        "INSERT INTO links_new SELECT id, source, target, relative, kind FROM links",
    ),
    "a column added": (
        "CREATE TABLE links_new (id INTEGER PRIMARY KEY, source INTEGER NOT NULL, target INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('odometry', 'loop')), "
        "distance_m REAL NOT NULL, duration_s REAL NOT NULL, note TEXT)",
        "INSERT INTO links_new SELECT *, NULL FROM links",
    ),
    "a column of another type": (
        "CREATE TABLE links_new (id INTEGER PRIMARY KEY, source INTEGER NOT NULL, target INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('odometry', 'loop')), distance_m TEXT NOT NULL, "
        "duration_s REAL NOT NULL)",
        "INSERT INTO links_new SELECT * FROM links",
    ),
}


@pytest.mark.parametrize("case", list(REBUILT))
def test_a_table_rebuilt_with_other_columns_is_refused_by_name(tmp_path, stored, case):
    make, copy = REBUILT[case]
    path = tmp_path / "map.neoslam"
    path.write_bytes(stored)
    _edited(path, make, copy, "DROP TABLE links", "ALTER TABLE links_new RENAME TO links")
    line = _refused(path, "table links: columns (")
    assert "differ from the format's" in line or "differ in type" in line


def test_a_table_with_other_constraints_is_refused(tmp_path, stored):
    path = tmp_path / "map.neoslam"
    path.write_bytes(stored)
    _edited(
        path,
        "CREATE TABLE links_new (id INTEGER PRIMARY KEY, source INTEGER NOT NULL, target INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL, distance_m REAL NOT NULL, duration_s REAL NOT NULL)",  # no CHECK
        "INSERT INTO links_new SELECT * FROM links",
        "DROP TABLE links",
        "ALTER TABLE links_new RENAME TO links",
    )
    _refused(path, "table links: defined otherwise than the format's")


def test_a_foreign_log_beside_a_map_is_one_line_and_both_are_left_as_they_were(tmp_path, stored):
    """Another database's log beside the map: SQLite applies its frames to the map's pages and finds them damaged
    (a complaint for every page): one line, and neither file changed."""
    path = tmp_path / "map.neoslam"
    path.write_bytes(stored)
    other = sqlite3.connect(tmp_path / "other.sqlite")
    try:
        other.execute("PRAGMA journal_mode = WAL")
        other.execute("PRAGMA wal_autocheckpoint = 0")
        other.execute("CREATE TABLE t (x BLOB)")
        other.executemany("INSERT INTO t VALUES (randomblob(?))", [(3000 + i,) for i in range(60)])
        other.commit()
        Path(f"{path}-wal").write_bytes(Path(tmp_path / "other.sqlite-wal").read_bytes())
    finally:
        other.close()
    for read_only in (False, True):
        _refused(path, "map.neoslam: ", read_only=read_only)


def test_a_statement_that_runs_long_stops_on_ctrl_c(tmp_path, stored):
    """SQLite gives Python's signal handlers a turn while a statement runs: SIGINT (here with Python's own handler,
    which raises KeyboardInterrupt) stops it within a moment. Should it not, SQLite is interrupted after
    GIVE_UP_S and the test fails on the time taken rather than hanging."""
    path = tmp_path / "map.neoslam"
    path.write_bytes(stored)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # whatever an earlier test left
    try:
        with MapFile.open(path, CONFIG, read_only=True) as map_file:
            connection = map_file._open_connection
            ctrl_c = threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT))
            give_up = threading.Timer(GIVE_UP_S, connection.interrupt)
            started = time.monotonic()
            ctrl_c.start()
            give_up.start()
            try:
                with pytest.raises(sqlite3.OperationalError) as caught:
                    connection.execute(
                        "WITH RECURSIVE n(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM n) SELECT count(*) FROM n"
                    ).fetchone()
            finally:
                ctrl_c.cancel()
                give_up.cancel()
            assert interrupted(caught.value)
            assert time.monotonic() - started < GIVE_UP_S - 1.0, "not stopped by the signal"
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.fixture
def small_disk(tmp_path: Path):
    """A 2 MiB filesystem (tmpfs) in the test's folder; skipped where this user may not mount one."""
    mount = tmp_path / "disk"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mount)], capture_output=True)
    if made.returncode != 0:
        pytest.skip(f"cannot mount a small filesystem here ({made.stderr.decode(errors='replace').strip()})")
    try:
        yield mount
    finally:
        subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def test_a_full_disk_under_a_map_is_one_line_and_the_map_stays_as_last_committed(small_disk):
    path = small_disk / "map.neoslam"
    growth = Growth()
    committed = None
    with pytest.raises(OutputError) as caught:
        map_file = MapFile.create(path, CONFIG)
        try:
            for step in range(2, 400, 2):
                state = growth.state(step)
                map_file.commit(state)
                committed = state
        finally:
            map_file.close()
    assert committed is not None
    line = str(caught.value)
    assert "\n" not in line and "the disk is full" in line and line.startswith(str(path)), line
    with MapFile.open(path, CONFIG, read_only=True) as reread:  # read from a private copy, off the full disk
        loaded = reread.load()
    assert len(loaded.experiences) == len(committed.experiences)
    assert len(loaded.keyframes) == len(committed.keyframes)
