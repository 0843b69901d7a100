"""The map file: one SQLite database that holds a NeoSLAM map and grows at every keyframe of a run.

A run writes its map into the file as it goes, one transaction per `commit` (only what is new or changed since the
last one), so that a killed run leaves the map up to its last committed keyframe; a later session opens the file,
`load`s it and extends it. While a run writes, the file is in SQLite's write-ahead-log mode (beside it `MAP-wal`);
`close` folds the log back and leaves one self-contained file. The same commits give the same file, byte for byte:
nothing in it depends on the clock.

Format (format_version 5). Every array is a BLOB of little-endian raw bytes: float64 (`<f8`) unless said otherwise,
of the shape its column fixes or its row's columns give. Ids are the map's own: keyframe, experience and object ids;
links, closures and OVCN losses are numbered by their position in the map's lists.

| table | columns |
|---|---|
| `meta` | `key`, `value` (text): `format` = `neoslam-map`, `format_version` = `4`, `neoslam_version`, `config` (the config the map was made with, as JSON) |
| `sessions` | `id`, `name` (dataset; a BLOB of its bytes when they are not UTF-8), `frames`, `relocalised_frame` (null: not joined the stored map) |
| `keyframes` | `id`, `frame`, `experience` (null: none), `pose` (4x4), `objects` (n), `centers` (n x 3), `labels` (JSON list of n strings), `patch_height`, `patch_width`, `patches` (n x h x w uint8), `provisional` (n uint8, 1: an object not known to be static yet), `covariances` (n x 2 x 2: each centre's ground-plane covariance from its views, m²) |
| `experiences` | `id`, `session`, `frame`, `grid_cell` (3), `head_direction` (real, cells), `odometry_pose` (4x4), `linear_velocity` (3), `angular_velocity` (3), `keyframe` (null: none) |
| `experience_poses` | `block`, `poses` (k x 4 x 4): the corrected poses, map frame, of experiences 30·block to 30·block + k - 1 (k = 30 but in the last block); blocks, not a row per experience, since a correction moves every pose: 1500 experiences are 50 rows of one page each |
| `links` | `id`, `source`, `target` (experiences), `relative` (4x4, T_source_target), `kind` (`odometry` or `loop`), `distance_m`, `duration_s` (travelled and elapsed along an odometry link; 0 for a loop link) |
| `withdrawn_links` | `link` (a loop link's id): links withdrawn because the optimised map disagreed with them (neoslam.mapping.healing); they stay in `links`, out of the map |
| `closures` | `id`, `session`, `match_session`, `query_frame`, `match_frame`, `query_keyframe`, `match_keyframe`, `score`, `n_matches`, `relative_pose` (4x4, T_match_query) |
| `objects` | `id`, `label`, `sums` (3, weighted world sums), `weight`, `count` (0: merged away or forgotten) |
| `object_observations` | `object`, `experience` (together the primary key), `sums` (3, in the experience's frame), `weight`, `count` |
| `hebbian` | `keyframe`, `gc_cells` (n), `gc_indices` (n int32), `gc_weights` (n float32), `hd_cells` (m), `hd_indices` (m int32), `hd_weights` (m float32), `gc_peak_x`, `gc_peak_y`, `gc_peak_z`, `hd_peak`, `strength` |
| `object_vector` | `position`, `name` (OVCN parameter), `dtype` (`<f4` or `<f8`), `shape` (JSON list), `data` |
| `object_vector_losses` | `epoch` (from 0), `loss` |

The file header's application_id is 0x4E534C4D ("NSLM") and its user_version the format_version. Object ids are
row numbers (0 .. n-1); observations load sorted by (object, experience).

A map is opened only by the NeoSLAM version that made it and with the same settings of the sections in
MAP_SECTIONS; anything else (and a file that is not a map, or is corrupt, down to one value that is not finite or
one id no row has: neoslam.store.reading) is refused with one line naming the problem, and a refused file is never
modified: it is read whole and checked before it is opened for writing. A run holds the file locked while it writes (a second run is refused:
"in use"). Every commit survives a killed process; `map_store.synchronous: full` makes it survive a power cut too.
A map a killed run left in write-ahead-log mode is recovered by the next run that opens it for writing; opened
read-only it is read from a private copy of it and its log, and left exactly as it is.

Here: making, opening (connections, the lock, private copies) and closing the file, loading, and committing. Whether a
file may be opened is decided in neoslam.store.validation, whether its rows hold a map in neoslam.store.reading, what
a commit writes in neoslam.store.changes.
"""  # noqa: E501

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import tempfile
from contextlib import suppress
from pathlib import Path
from types import TracebackType
from urllib.parse import quote

from neoslam import __version__
from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError, OutputError
from neoslam.store.changes import WrittenState
from neoslam.store.reading import CorruptRow, MapLimits, first_line, read_state
from neoslam.store.schema import APPLICATION_ID, FORMAT_TAG, FORMAT_VERSION, STATEMENTS, TABLES, columns
from neoslam.store.validation import MAP_SECTIONS, interrupted, locked, read_header, validate
from neoslam.types import MapState

__all__ = ["MAP_SECTIONS", "MapFile"]

_PROGRESS_STEPS = 100_000  # SQLite virtual-machine steps between the signal handlers' turns (well under 0.1 s)
_BUSY_TIMEOUT_S = 0.25  # a map in use stays locked for the whole run: waiting longer would not help
_SCRATCH = "neoslam-map-"  # private copies of maps read-only: neoslam-map-<pid>-<random> in the temporary folder


class MapFile:
    """A NeoSLAM map in one SQLite file. Make one with `create` or `open`, never directly; use it as a context
    manager or `close` it (which leaves one self-contained file)."""

    def __init__(
        self,
        path: Path,
        connection: sqlite3.Connection,
        read_only: bool,
        scratch: Path | None,
        limits: MapLimits,
        read: MapState | None = None,
    ) -> None:
        self.path = path
        self.read_only = read_only
        self._connection: sqlite3.Connection | None = connection
        self._scratch = scratch  # a private copy a read-only map is read from (a map left with a write-ahead log)
        self._limits = limits
        self._read = read  # the map as open() read and checked it, which the first load() gives
        self._written: WrittenState | None = WrittenState() if read is None else None  # None: load() before commit()

    @classmethod
    def create(cls, path: Path, config: NeoSLAMConfig) -> MapFile:
        """A new, empty map at `path` (refused if anything is there). The file appears whole: schema and meta are
        made under a temporary name beside it and linked into place."""
        path = Path(path)
        if path.exists() or path.is_symlink():
            raise OutputError(f"{path}: exists already; open it to extend the map, or name a new file")
        if not path.parent.is_dir():
            raise OutputError(f"{path}: the folder {path.parent} does not exist")
        partial = path.with_name(f".{path.name}.partial-{os.getpid()}")
        partial.unlink(missing_ok=True)
        try:
            connection = _hardened(sqlite3.connect(partial, isolation_level=None))
            try:
                _make_schema(connection, config)
            finally:
                connection.close()
            os.link(partial, path)  # refuses, atomically, a file another process made meanwhile
        except FileExistsError:
            raise OutputError(f"{path}: exists already; open it to extend the map, or name a new file") from None
        except (OSError, sqlite3.Error) as error:
            raise OutputError(f"{path}: cannot create the map file ({error})") from None
        finally:
            for leftover in (partial, Path(f"{partial}-journal")):
                leftover.unlink(missing_ok=True)
        _sync_folder(path.parent)
        return cls(path, _writer(path, config), read_only=False, scratch=None, limits=_limits(config))

    @classmethod
    def open(cls, path: Path, config: NeoSLAMConfig, read_only: bool = False) -> MapFile:
        """An existing map, read whole and checked before anything is written to it: refused with InputError (the
        file untouched) when it is not a NeoSLAM map, is corrupt (down to a value that is not finite or an id no
        row has), or was made by another version or with another config. Only then is it opened for writing."""
        path = Path(path)
        header = read_header(path)
        limits = _limits(config)
        connection, scratch = _reader(path, header)
        try:
            validate(connection, path, config)
            state = _read_state(connection, path, limits)
            seen = _summary(connection, path)
        except InputError as error:
            connection.close()
            _remove(scratch)
            log = _side_file(path, "-wal")
            if scratch is None or not log.exists():
                raise
            raise InputError(path, f"{error.problem}, as read with the log {log.name} beside it") from None
        except BaseException:
            connection.close()
            _remove(scratch)
            raise
        if read_only:
            connection.execute("PRAGMA query_only = ON")
            return cls(path, connection, read_only=True, scratch=scratch, limits=limits, read=state)
        connection.close()
        _remove(scratch)
        map_file = cls(path, _writer(path, config), read_only=False, scratch=None, limits=limits, read=state)
        if _summary(map_file._open_connection, path) != seen:  # another run wrote it between the read and the lock
            map_file.close()
            raise InputError(path, "changed by another run while this one opened it; run again")
        return map_file

    def __enter__(self) -> MapFile:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, value: BaseException | None, traceback: TracebackType | None
    ) -> None:
        if value is None:
            self.close()
            return
        with suppress(OutputError):  # the error on the way out says what went wrong; a full disk fails both
            self.close()

    @property
    def _open_connection(self) -> sqlite3.Connection:
        if self._connection is None:
            raise RuntimeError(f"{self.path}: the map file is closed")
        return self._connection

    def load(self) -> MapState:
        """Everything the file holds; it also becomes what the next commit is compared against."""
        connection = self._open_connection
        state, self._read = self._read, None
        if state is None:
            state = _read_state(connection, self.path, self._limits)
        self._written = WrittenState.of(state)
        return state

    def commit(self, state: MapState) -> None:
        """Write, in one transaction, everything in `state` that is new or changed since the last commit (or load).
        Keyframes, experiences, links, closures and OVCN losses only grow; what was written of them is not
        compared again, except the experiences' corrected poses and the keyframes' experiences."""
        if self.read_only:
            raise RuntimeError(f"{self.path}: the map was opened read-only; nothing is written to it")
        connection = self._open_connection
        if self._written is None:
            raise RuntimeError(f"{self.path}: load() the map before committing to it (the file holds a map)")
        operations, written = self._written.changes(state)
        if not operations:
            return
        try:
            connection.execute("BEGIN IMMEDIATE")
            for statement, rows in operations:
                connection.executemany(STATEMENTS[statement], rows)
            connection.execute("COMMIT")
        except BaseException as error:
            with suppress(sqlite3.Error):  # a full disk may refuse the rollback too; SQLite undoes it on close
                if connection.in_transaction:
                    connection.execute("ROLLBACK")
            if isinstance(error, sqlite3.Error) and not interrupted(error):
                raise OutputError(
                    f"{self.path}: cannot write the map ({_writing_problem(error)}); it is as it was at its last commit"
                ) from None
            raise
        self._written = written

    def close(self) -> None:
        """Fold the write-ahead log into the file and leave it in rollback-journal mode: one self-contained file."""
        connection, self._connection = self._connection, None
        if connection is None:
            return
        try:
            if not self.read_only:
                connection.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                connection.execute("PRAGMA journal_mode = DELETE")
        except sqlite3.Error as error:
            if interrupted(error):
                raise KeyboardInterrupt from None
            raise OutputError(
                f"{self.path}: the map is whole up to its last commit, but its log {self.path.name}-wal could not "
                f"be folded into it ({_writing_problem(error)}); the next run that opens the map does it"
            ) from None
        finally:
            with suppress(sqlite3.Error):  # the log stays beside the map when it cannot be folded in
                connection.close()
            _remove(self._scratch)
            self._scratch = None


def _writing_problem(error: sqlite3.Error) -> str:
    """What SQLite's refusal to write means, in one line."""
    if isinstance(error, sqlite3.OperationalError) and "full" in str(error):
        return "the disk is full"
    return first_line(str(error))


# Reading


def _read_state(connection: sqlite3.Connection, path: Path, limits: MapLimits) -> MapState:
    """The map the file holds, every value checked; InputError naming the table and row of the first problem."""
    try:
        return read_state(connection, limits)
    except CorruptRow as error:
        raise InputError(path, f"corrupt map file ({error})") from None
    except sqlite3.Error as error:
        if interrupted(error):
            raise KeyboardInterrupt from None
        if locked(error):
            raise InputError(path, "in use by another run (the map file is locked)") from None
        raise InputError(path, f"corrupt map file ({first_line(str(error))})") from None
    except (ValueError, KeyError, TypeError, OverflowError) as error:  # a row the checks did not foresee
        raise InputError(path, f"corrupt map file ({error})") from None
    except MemoryError:
        raise InputError(path, "too large to load into this machine's memory") from None


def _summary(connection: sqlite3.Connection, path: Path) -> tuple[object, ...]:
    """What any commit changes (every commit writes its session's row), to tell whether the file changed."""
    try:
        sessions = connection.execute(f"SELECT {columns('sessions')} FROM sessions ORDER BY id").fetchall()
        counts = connection.execute(
            "SELECT (SELECT count(*) FROM keyframes), (SELECT count(*) FROM experiences), (SELECT count(*) FROM links)"
        ).fetchone()
    except sqlite3.Error as error:
        if interrupted(error):
            raise KeyboardInterrupt from None
        raise InputError(path, f"corrupt map file ({first_line(str(error))})") from None
    return tuple(sessions), tuple(counts)


def _limits(config: NeoSLAMConfig) -> MapLimits:
    """What the config fixes about a map's contents (the OVCN's parameter shapes asked of the OVCN itself, only for
    a map that holds OVCN weights)."""
    return MapLimits(
        grid_cells=tuple(int(size) for size in config.grid_cells.dims),
        head_direction_cells=int(config.head_direction.cells),
        epochs=int(config.object_vector.epochs),
        object_vector_shapes=lambda: _object_vector_shapes(config),
    )


def _object_vector_shapes(config: NeoSLAMConfig) -> dict[str, tuple[int, ...]]:
    from neoslam.cells.object_vector import ObjectVectorCells  # here: torch loads in a second, and few maps need it

    return {name: tuple(value.shape) for name, value in ObjectVectorCells(config.object_vector).weights().items()}


# Connections and the file beside them


def _side_file(path: Path, suffix: str) -> Path:
    return path.with_name(path.name + suffix)


def _reader(path: Path, header: bytes) -> tuple[sqlite3.Connection, Path | None]:
    """A connection that reads the map without changing the file or leaving anything beside it. A map in rollback
    mode with no journal beside it (a closed map) is read in place, read-only; one left in write-ahead-log mode or
    with a journal (a run killed, or still running) is read from a private copy of it and its log."""
    wal_mode = header[18] == 2 or header[19] == 2
    if not wal_mode and not any(_side_file(path, s).exists() for s in ("-wal", "-journal", "-shm")):
        uri = f"file:{quote(str(path.absolute()))}?mode=ro"
        return _hardened(sqlite3.connect(uri, uri=True, isolation_level=None, timeout=_BUSY_TIMEOUT_S)), None
    _sweep_scratch()
    scratch = Path(tempfile.mkdtemp(prefix=f"{_SCRATCH}{os.getpid()}-"))
    copy = scratch / "map.sqlite"
    try:
        shutil.copyfile(path, copy)
        for suffix in ("-wal", "-journal"):
            with suppress(FileNotFoundError):  # none beside it, or gone meanwhile
                shutil.copyfile(_side_file(path, suffix), _side_file(copy, suffix))
        return _hardened(sqlite3.connect(copy, isolation_level=None, timeout=_BUSY_TIMEOUT_S)), scratch
    except (OSError, sqlite3.Error) as error:
        _remove(scratch)
        raise InputError(path, f"cannot be read ({error})") from None


def _writer(path: Path, config: NeoSLAMConfig) -> sqlite3.Connection:
    """The connection a run writes with: write-ahead log, the configured durability, and an exclusive lock held
    until close (one process writes a map at a time; no shared-memory file beside it)."""
    connection = _hardened(sqlite3.connect(path, isolation_level=None, timeout=_BUSY_TIMEOUT_S))
    try:
        connection.execute("PRAGMA locking_mode = EXCLUSIVE")
        mode = connection.execute("PRAGMA journal_mode = WAL").fetchone()[0]
        if mode != "wal":
            raise sqlite3.OperationalError(f"journal mode {mode}, not wal")
        connection.execute(f"PRAGMA synchronous = {config.map_store.synchronous.upper()}")
        connection.execute("BEGIN EXCLUSIVE")  # take the lock now
        connection.execute("COMMIT")
    except sqlite3.Error as error:
        connection.close()
        if interrupted(error):
            raise KeyboardInterrupt from None
        if locked(error):
            raise InputError(path, "in use by another run (the map file is locked)") from None
        raise InputError(path, f"cannot be opened for writing ({first_line(str(error))})") from None
    return connection


def _hardened(connection: sqlite3.Connection) -> sqlite3.Connection:
    """A connection fit for a file from anywhere: SQL in its schema is not trusted (`trusted_schema` off; defensive
    mode too where Python can set it, 3.12 on), and every PROGRESS_STEPS steps of a statement Python's signal
    handlers get a turn, so that Ctrl-C stops a statement that runs long (SQLite then says `interrupted`)."""
    connection.execute("PRAGMA trusted_schema = OFF")
    if hasattr(connection, "setconfig"):
        connection.setconfig(sqlite3.SQLITE_DBCONFIG_DEFENSIVE, True)
    connection.set_progress_handler(_signals_turn, _PROGRESS_STEPS)
    return connection


def _signals_turn() -> int:
    return 0  # 0: go on; a signal's handler runs before this returns (and, raising, interrupts the statement)


def _make_schema(connection: sqlite3.Connection, config: NeoSLAMConfig) -> None:
    meta = [
        ("format", FORMAT_TAG),
        ("format_version", str(FORMAT_VERSION)),
        ("neoslam_version", __version__),
        ("config", json.dumps(config.model_dump(mode="json"))),
    ]
    connection.execute("PRAGMA synchronous = FULL")
    connection.execute("BEGIN")
    connection.execute(f"PRAGMA application_id = {APPLICATION_ID}")
    connection.execute(f"PRAGMA user_version = {FORMAT_VERSION}")
    for statement in TABLES.values():
        connection.execute(statement)
    connection.executemany("INSERT INTO meta (key, value) VALUES (?, ?)", meta)
    connection.execute("COMMIT")


def _sync_folder(folder: Path) -> None:
    """Make a new name in `folder` durable (POSIX; a no-op where folders cannot be opened)."""
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)


def _sweep_scratch() -> None:
    """Remove the private copies that runs killed while reading a map left in the temporary folder."""
    for folder in Path(tempfile.gettempdir()).glob(f"{_SCRATCH}*-*"):
        pid = folder.name[len(_SCRATCH) :].split("-", 1)[0]
        if pid.isdigit() and not _alive(int(pid)):
            _remove(folder)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # alive, another user's
        return True
    return True


def _remove(scratch: Path | None) -> None:
    if scratch is not None:
        shutil.rmtree(scratch, ignore_errors=True)
