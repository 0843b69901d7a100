"""Reading a map file's rows back into a MapState, every value checked on the way (see neoslam.store.map_file): a
row that does not hold what its columns say (a BLOB of the wrong size, a value that is not finite, text that is not
JSON, an id no row has) is a CorruptRow naming its table, its row and the problem.

The tables are read in an order in which every reference points to a table read before (but a keyframe's
experience, checked once the experiences are read), row by row from the cursor, so that a corrupt row stops the
reading where it is met and no table is held twice in memory.
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, NoReturn

import numpy as np

from neoslam.store.schema import (
    F4,
    F8,
    FLOAT_DTYPES,
    I4,
    POSE,
    POSE_BLOCK,
    U1,
    VECTOR,
    columns,
    decode,
    read_name,
)
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

__all__ = ["CorruptRow", "MapLimits", "first_line", "read_state"]

_MESSAGE_CHARS = 200  # SQLite's complaint about a damaged file is clipped to its first line and this many characters

_MAX_ID = 2**31 - 1  # observation keys pack an object and an experience id in 32 bits each
_MAX_JSON_DEPTH = 4  # labels and shapes are flat lists; deeper nesting is not a map's, and json recurses on it


class CorruptRow(ValueError):
    """A row that does not hold what its table's columns say."""

    def __init__(self, table: str, row: str | None, problem: str) -> None:
        self.table, self.row, self.problem = table, row, problem
        super().__init__(f"table {table}{'' if row is None else f', row {row}'}: {problem}")


@dataclass(frozen=True)
class MapLimits:
    """What the config a map is opened with fixes about its contents: the cells' shapes (bounds of the Hebbian
    traces' indices and peaks), the OVCN's epochs and its parameters' shapes (None: not checked)."""

    grid_cells: tuple[int, int, int] | None = None
    head_direction_cells: int | None = None
    epochs: int | None = None
    object_vector_shapes: Callable[[], Mapping[str, tuple[int, ...]]] | None = None


def _refused(table: str, error: sqlite3.Error) -> Exception:
    """A CorruptRow of SQLite's first complaint about a table (a file may make it repeat one for every page); a
    lock stays SQLite's error, and a statement a signal interrupted is the KeyboardInterrupt it was."""
    if isinstance(error, sqlite3.OperationalError) and str(error) == "interrupted":
        return KeyboardInterrupt()
    if "locked" in str(error):
        return error
    return CorruptRow(table, None, first_line(str(error)))


class _Row:
    """The checks of one table's values, naming the table and the row being read when one fails."""

    def __init__(self, table: str) -> None:
        self.table = table
        self.key = "?"

    def at(self, **key: Any) -> _Row:
        self.key = ", ".join(f"{name} {value!r}" for name, value in key.items())
        return self

    def fail(self, problem: str) -> NoReturn:
        raise CorruptRow(self.table, self.key, problem)

    def integer(self, value: Any, column: str, low: int = 0, high: int = _MAX_ID) -> int:
        if not isinstance(value, int) or isinstance(value, bool):
            self.fail(f"{column} is {_kind(value)}, not an integer")
        if not low <= value <= high:
            self.fail(f"{column} is {value}, outside {low} .. {high}")
        return value

    def optional_integer(self, value: Any, column: str, low: int = 0, high: int = _MAX_ID) -> int | None:
        return None if value is None else self.integer(value, column, low, high)

    def real(self, value: Any, column: str) -> float:
        if not isinstance(value, int | float) or isinstance(value, bool):
            self.fail(f"{column} is {_kind(value)}, not a number")
        if not math.isfinite(value):
            self.fail(f"non-finite value {value} in {column}")
        return float(value)

    def text(self, value: Any, column: str) -> str:
        if not isinstance(value, str):
            self.fail(f"{column} is {_kind(value)}, not text")
        return value

    def array(self, blob: Any, dtype: np.dtype, shape: tuple[int, ...], column: str, writable: bool = True) -> Any:
        """The array a BLOB holds; a float array must be finite."""
        if not isinstance(blob, bytes):
            self.fail(f"{column} is {_kind(blob)}, not a BLOB")
        try:
            values = decode(blob, dtype, shape, writable)
        except ValueError as error:
            self.fail(f"{column}: {error}")
        if values.dtype.kind == "f" and not np.isfinite(values).all():
            self.fail(f"non-finite value {_first_non_finite(values)} in {column}")
        return values

    def json_list(self, value: Any, column: str) -> list[Any]:
        text = self.text(value, column)
        if _depth(text) > _MAX_JSON_DEPTH:
            self.fail(f"{column} is not a flat JSON list")
        try:
            items = json.loads(text)
        except ValueError as error:
            self.fail(f"{column} is not JSON ({error})")
        if not isinstance(items, list):
            self.fail(f"{column} is not a JSON list")
        return items


def _kind(value: Any) -> str:
    if value is None:
        return "NULL"
    if isinstance(value, bytes):
        return f"a {len(value)}-byte BLOB"
    if isinstance(value, str):
        return f"the text {value[:20]!r}" + ("..." if len(value) > 20 else "")
    return repr(value)


def _first_non_finite(values: np.ndarray) -> str:
    value = values.flat[int(np.flatnonzero(~np.isfinite(values.ravel()))[0])]
    return "NaN" if np.isnan(value) else ("inf" if value > 0 else "-inf")


def _depth(text: str) -> int:
    """The deepest nesting of brackets outside strings, counted without parsing (json.loads recurses on it)."""
    depth = deepest = 0
    in_string = escaped = False
    for char in text:
        if in_string:
            escaped, in_string = (False, True) if escaped else (char == "\\", char != '"')
        elif char == '"':
            in_string = True
        elif char in "[{":
            depth += 1
            deepest = max(deepest, depth)
            if deepest > _MAX_JSON_DEPTH:
                break
        elif char in "]}":
            depth -= 1
    return deepest


def first_line(text: str) -> str:
    """The first line of a message, clipped (SQLite may list a complaint for every page of a damaged file)."""
    line = text.strip().splitlines()[0] if text.strip() else text
    return line if len(line) <= _MESSAGE_CHARS else f"{line[: _MESSAGE_CHARS - 3]}..."


def read_state(connection: sqlite3.Connection, limits: MapLimits = MapLimits()) -> MapState:
    """Everything a map file holds; CorruptRow for a row that holds it wrongly (sqlite3.DatabaseError for a file
    SQLite cannot read)."""

    def rows(sql: str) -> Iterator[tuple[Any, ...]]:
        """The rows of a query; SQLite's refusal of one (text that is not UTF-8, a damaged page) names the table
        (a lock is the caller's to report)."""
        table = sql.split(" FROM ")[1].split()[0]
        try:
            cursor = connection.execute(sql)
        except sqlite3.Error as error:
            raise _refused(table, error) from None
        while True:
            try:
                row = cursor.fetchone()
            except sqlite3.Error as error:
                raise _refused(table, error) from None
            if row is None:
                return
            yield row

    state = MapState()
    check = _Row("sessions")
    for session_id, name, frames, relocalised in rows(f"SELECT {columns('sessions')} FROM sessions ORDER BY id"):
        check.at(id=session_id)
        if not isinstance(name, str | bytes):
            check.fail(f"name is {_kind(name)}, not text")
        state.sessions.append(
            SessionRecord(
                check.integer(session_id, "id", 1),
                read_name(name),
                check.integer(frames, "frames"),
                check.optional_integer(relocalised, "relocalised_frame"),
            )
        )
    sessions = {record.id for record in state.sessions}
    _read_keyframes(rows, state)
    _read_experiences(rows, state, sessions)
    _read_graph(rows, state, sessions)
    state.objects = _read_objects(rows, len(state.experiences))
    _read_hebbian(rows, state, limits)
    _read_object_vector(rows, state, limits)
    return state


def _read_keyframes(rows, state: MapState) -> None:
    check = _Row("keyframes")
    for kf_id, frame, experience, pose, n, centers, labels, height, width, patches, provisional, covariances in rows(
        f"SELECT {columns('keyframes')} FROM keyframes ORDER BY id"
    ):
        check.at(id=kf_id)
        n = check.integer(n, "objects")
        height, width = check.integer(height, "patch_height"), check.integer(width, "patch_width")
        names = tuple(check.json_list(labels, "labels"))
        if len(names) != n or not all(isinstance(name, str) for name in names):
            check.fail(f"labels holds {len(names)} items for {n} objects, not a string each")
        state.keyframes.append(
            Keyframe(
                check.integer(kf_id, "id"),
                check.integer(frame, "frame"),
                check.array(pose, F8, POSE, "pose"),
                check.array(centers, F8, (n, 3), "centers"),
                names,
                check.array(patches, U1, (n, height, width), "patches"),
                check.array(provisional, U1, (n,), "provisional").astype(bool),
                check.array(covariances, F8, (n, 2, 2), "covariances"),
            )
        )
        experience = check.optional_integer(experience, "experience")
        if experience is not None:
            state.keyframe_experience[kf_id] = experience


def _read_experiences(rows, state: MapState, sessions: set[int]) -> None:
    check = _Row("experiences")
    keyframes = {keyframe.id for keyframe in state.keyframes}
    for exp_id, session, frame, grid, heading, pose, linear, angular, keyframe in rows(
        f"SELECT {columns('experiences')} FROM experiences ORDER BY id"
    ):
        check.at(id=exp_id)
        if exp_id != len(state.experiences):
            check.fail(f"where id {len(state.experiences)} was expected (ids count from 0)")
        if check.integer(session, "session", 1) not in sessions:
            check.fail(f"session {session} is not in table sessions")
        if check.optional_integer(keyframe, "keyframe") not in keyframes | {None}:
            check.fail(f"keyframe {keyframe} is not in table keyframes")
        state.experiences.append(
            Experience(
                exp_id,
                check.integer(frame, "frame"),
                check.array(grid, F8, VECTOR, "grid_cell"),
                check.real(heading, "head_direction"),
                check.array(pose, F8, POSE, "odometry_pose"),
                check.array(linear, F8, VECTOR, "linear_velocity"),
                check.array(angular, F8, VECTOR, "angular_velocity"),
                keyframe,
                session,
            )
        )
    check = _Row("keyframes")
    for keyframe_id, experience in state.keyframe_experience.items():
        if experience >= len(state.experiences):
            check.at(id=keyframe_id).fail(f"experience {experience} is not in table experiences")
    n = len(state.experiences)
    blocks = []
    check = _Row("experience_poses")
    for block, poses in rows("SELECT block, poses FROM experience_poses ORDER BY block"):
        check.at(block=block)
        if block != len(blocks):
            check.fail(f"where block {len(blocks)} was expected (the corrected poses skip a block)")
        k = min(POSE_BLOCK, n - block * POSE_BLOCK)
        if k <= 0:
            check.fail(f"a block beyond the {n} experiences")
        blocks.append(check.array(poses, F8, (k, *POSE), "poses", writable=False))
    if len(blocks) * POSE_BLOCK < n:
        check.at(block=len(blocks)).fail(f"missing: {len(blocks) * POSE_BLOCK} corrected poses for {n} experiences")
    state.experience_poses = np.concatenate(blocks) if blocks else np.zeros((0, *POSE))


def _read_graph(rows, state: MapState, sessions: set[int]) -> None:
    last = len(state.experiences) - 1
    check = _Row("links")
    for position, (link_id, source, target, relative, kind, distance, duration) in enumerate(
        rows(f"SELECT {columns('links')} FROM links ORDER BY id")
    ):
        check.at(id=link_id)
        _check_position(check, link_id, position)
        if kind not in ("odometry", "loop"):
            check.fail(f"kind is {_kind(kind)}, not 'odometry' or 'loop'")
        if check.real(duration, "duration_s") < 0:
            check.fail(f"duration_s is {duration}: a link spans no negative time")
        state.links.append(
            Link(
                check.integer(source, "source", 0, last),
                check.integer(target, "target", 0, last),
                check.array(relative, F8, POSE, "relative"),
                kind,
                check.real(distance, "distance_m"),
                float(duration),
            )
        )
    check = _Row("withdrawn_links")
    for (link,) in rows("SELECT link FROM withdrawn_links ORDER BY link"):
        check.at(link=link)
        index = check.integer(link, "link", 0, len(state.links) - 1)
        if state.links[index].kind != "loop":
            check.fail("names an odometry link: only loop links are withdrawn")
        state.withdrawn_links.append(index)
    check = _Row("closures")
    for position, (closure_id, session, match_session, *numbers, relative) in enumerate(
        rows(f"SELECT {columns('closures')} FROM closures ORDER BY id")
    ):
        check.at(id=closure_id)
        _check_position(check, closure_id, position)
        for column, value in (("session", session), ("match_session", match_session)):
            if check.integer(value, column, 1) not in sessions:
                check.fail(f"{column} {value} is not in table sessions")
        query_frame, match_frame, query_keyframe, match_keyframe, score, n_matches = numbers
        closure = LoopClosure(
            check.integer(query_frame, "query_frame"),
            check.integer(match_frame, "match_frame"),
            check.integer(query_keyframe, "query_keyframe"),
            check.integer(match_keyframe, "match_keyframe"),
            check.real(score, "score"),
            check.integer(n_matches, "n_matches"),
            check.array(relative, F8, POSE, "relative_pose"),
        )
        state.closures.append(StoredClosure(session, match_session, closure))


def _read_objects(rows, experiences: int) -> ObjectMapState:
    labels, sums, weights, counts = [], [], [], []
    check = _Row("objects")
    for position, (object_id, label, object_sums, weight, count) in enumerate(
        rows(f"SELECT {columns('objects')} FROM objects ORDER BY id")
    ):
        check.at(id=object_id)
        _check_position(check, object_id, position)
        labels.append(check.text(label, "label"))
        sums.append(check.array(object_sums, F8, VECTOR, "sums", writable=False))
        weights.append(check.real(weight, "weight"))
        counts.append(check.integer(count, "count"))
    owners, anchors, pair_sums, pair_weights, pair_counts = [], [], [], [], []
    check = _Row("object_observations")
    for owner, anchor, observed, weight, count in rows(
        f"SELECT {columns('object_observations')} FROM object_observations ORDER BY object, experience"
    ):
        check.at(object=owner, experience=anchor)
        owners.append(check.integer(owner, "object", 0, len(labels) - 1))
        anchors.append(check.integer(anchor, "experience", 0, experiences - 1))
        pair_sums.append(check.array(observed, F8, VECTOR, "sums", writable=False))
        pair_weights.append(check.real(weight, "weight"))
        pair_counts.append(check.integer(count, "count"))
    return ObjectMapState(
        labels=labels,
        sums=np.array(sums, dtype=float).reshape(-1, 3),
        weights=np.array(weights, dtype=float),
        counts=np.array(counts, dtype=int),
        pair_object=np.array(owners, dtype=int),
        pair_experience=np.array(anchors, dtype=int),
        pair_sums=np.array(pair_sums, dtype=float).reshape(-1, 3),
        pair_weights=np.array(pair_weights, dtype=float),
        pair_counts=np.array(pair_counts, dtype=int),
    )


def _read_hebbian(rows, state: MapState, limits: MapLimits) -> None:
    keyframes = {keyframe.id for keyframe in state.keyframes}
    dims = limits.grid_cells or (_MAX_ID, _MAX_ID, _MAX_ID)
    gc_cells = math.prod(dims) if limits.grid_cells else _MAX_ID
    hd_cells = limits.head_direction_cells or _MAX_ID
    check = _Row("hebbian")
    for keyframe, gc_n, gc_indices, gc_weights, hd_n, hd_indices, hd_weights, x, y, z, hd_peak, strength in rows(
        f"SELECT {columns('hebbian')} FROM hebbian ORDER BY keyframe"
    ):
        check.at(keyframe=keyframe)
        if check.integer(keyframe, "keyframe") not in keyframes:
            check.fail(f"keyframe {keyframe} is not in table keyframes")
        gc_n, hd_n = check.integer(gc_n, "gc_cells"), check.integer(hd_n, "hd_cells")
        gc = check.array(gc_indices, I4, (gc_n,), "gc_indices", writable=False)
        hd = check.array(hd_indices, I4, (hd_n,), "hd_indices", writable=False)
        for column, indices, cells in (("gc_indices", gc, gc_cells), ("hd_indices", hd, hd_cells)):
            if indices.size and (indices.min() < 0 or indices.max() >= cells):
                check.fail(f"{column} holds a cell outside 0 .. {cells - 1}")
        peak = tuple(
            check.integer(value, column, 0, size - 1)
            for value, column, size in zip((x, y, z), ("gc_peak_x", "gc_peak_y", "gc_peak_z"), dims, strict=True)
        )
        state.hebbian[keyframe] = HebbianTrace(
            gc,
            check.array(gc_weights, F4, (gc_n,), "gc_weights", writable=False),
            hd,
            check.array(hd_weights, F4, (hd_n,), "hd_weights", writable=False),
            peak,
            check.integer(hd_peak, "hd_peak", 0, hd_cells - 1),
            check.real(strength, "strength"),
        )


def _read_object_vector(rows, state: MapState, limits: MapLimits) -> None:
    expected: Mapping[str, tuple[int, ...]] | None = None
    check = _Row("object_vector")
    for position, (stored_position, name, dtype, shape, data) in enumerate(
        rows(f"SELECT {columns('object_vector')} FROM object_vector ORDER BY position")
    ):
        check.at(position=stored_position)
        if expected is None and limits.object_vector_shapes is not None:
            expected = limits.object_vector_shapes()
        _check_position(check, stored_position, position)
        name = check.text(name, "name")
        if dtype not in FLOAT_DTYPES:
            check.fail(f"dtype is {_kind(dtype)}, not '<f4' or '<f8'")
        dims = tuple(check.integer(size, "a size in shape") for size in check.json_list(shape, "shape"))
        if expected is not None and expected.get(name) != dims:
            wanted = "no such parameter" if name not in expected else f"shape {list(expected[name])}"
            check.fail(f"OVCN parameter {name!r} of shape {list(dims)}; the OVCN has {wanted}")
        state.object_vector_weights[name] = check.array(data, FLOAT_DTYPES[dtype], dims, "data")
    if expected is not None and state.object_vector_weights and state.object_vector_weights.keys() != expected.keys():
        missing = sorted(expected.keys() - state.object_vector_weights.keys())
        check.at(position=len(state.object_vector_weights)).fail(f"missing: OVCN parameter {missing[0]!r}")
    check = _Row("object_vector_losses")
    for position, (epoch, loss) in enumerate(
        rows(f"SELECT {columns('object_vector_losses')} FROM object_vector_losses ORDER BY epoch")
    ):
        check.at(epoch=epoch)
        _check_position(check, epoch, position)
        if limits.epochs is not None and position >= limits.epochs:
            check.fail(f"more epochs than the {limits.epochs} the OVCN learns (object_vector.epochs)")
        state.object_vector_losses.append(check.real(loss, "loss"))


def _check_position(check: _Row, stored_id: Any, position: int) -> None:
    if stored_id != position:
        check.fail(f"where id {position} was expected (ids count from 0)")
