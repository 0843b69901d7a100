"""The map file's SQLite schema and how records become rows (see neoslam.store.map_file for the format; opening the
file lives there, checking it in neoslam.store.validation, rows read back into records in neoslam.store.reading,
commits in neoslam.store.changes).

Every array is a BLOB of little-endian raw bytes of the dtype its column names (`<f8` unless said otherwise), with
its shape fixed by the column (a pose is 4x4) or given by other columns of the row. No pickle, no numpy headers.
"""

from __future__ import annotations

import json
import math
import sqlite3
from collections.abc import Mapping
from functools import cache
from typing import Any

import numpy as np

from neoslam.types import (
    Experience,
    HebbianTrace,
    Keyframe,
    Link,
    SessionRecord,
    StoredClosure,
)

__all__ = [
    "FORMAT_TAG",
    "FORMAT_VERSION",
    "APPLICATION_ID",
    "TABLES",
    "ColumnInfo",
    "columns",
    "format_schema",
    "table_columns",
    "F8",
    "F4",
    "I4",
    "U1",
    "FLOAT_DTYPES",
    "POSE",
    "POSE_BLOCK",
    "VECTOR",
    "encode",
    "decode",
    "decode_rows",
    "config_difference",
    "STATEMENTS",
    "session_row",
    "keyframe_row",
    "experience_row",
    "link_row",
    "closure_row",
    "hebbian_row",
    "stored_name",
    "read_name",
]

FORMAT_TAG = "neoslam-map"
FORMAT_VERSION = 5
APPLICATION_ID = 0x4E534C4D  # "NSLM" at offset 68 of the file header, so that `file` and others can tell a map

F8 = np.dtype("<f8")
F4 = np.dtype("<f4")
I4 = np.dtype("<i4")
U1 = np.dtype("u1")
FLOAT_DTYPES = {"<f4": F4, "<f8": F8}  # the dtypes an object_vector parameter may have
POSE = (4, 4)
POSE_SIZE = F8.itemsize * 16
POSE_BLOCK = 30  # corrected poses per row of experience_poses: 3840 bytes, a row that fills one 4096-byte page
VECTOR = (3,)

# Table name -> CREATE statement, in the order they are made. Ids are the components' own (keyframe, experience,
# object ids); links, closures and losses are numbered by their position in the map's lists.
TABLES: dict[str, str] = {
    "meta": "CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL) WITHOUT ROWID",
    "sessions": (
        "CREATE TABLE sessions (id INTEGER PRIMARY KEY, name TEXT NOT NULL, frames INTEGER NOT NULL, "
        "relocalised_frame INTEGER)"
    ),
    "keyframes": (
        "CREATE TABLE keyframes (id INTEGER PRIMARY KEY, frame INTEGER NOT NULL, experience INTEGER, "
        "pose BLOB NOT NULL, objects INTEGER NOT NULL, centers BLOB NOT NULL, labels TEXT NOT NULL, "
        "patch_height INTEGER NOT NULL, patch_width INTEGER NOT NULL, patches BLOB NOT NULL, "
        "provisional BLOB NOT NULL, covariances BLOB NOT NULL)"
    ),
    "experiences": (
        "CREATE TABLE experiences (id INTEGER PRIMARY KEY, session INTEGER NOT NULL, frame INTEGER NOT NULL, "
        "grid_cell BLOB NOT NULL, head_direction REAL NOT NULL, odometry_pose BLOB NOT NULL, "
        "linear_velocity BLOB NOT NULL, angular_velocity BLOB NOT NULL, keyframe INTEGER)"
    ),
    "experience_poses": "CREATE TABLE experience_poses (block INTEGER PRIMARY KEY, poses BLOB NOT NULL)",
    "links": (
        "CREATE TABLE links (id INTEGER PRIMARY KEY, source INTEGER NOT NULL, target INTEGER NOT NULL, "
        "relative BLOB NOT NULL, kind TEXT NOT NULL CHECK (kind IN ('odometry', 'loop')), distance_m REAL NOT NULL, "
        "duration_s REAL NOT NULL)"
    ),
    "withdrawn_links": "CREATE TABLE withdrawn_links (link INTEGER PRIMARY KEY)",
    "closures": (
        "CREATE TABLE closures (id INTEGER PRIMARY KEY, session INTEGER NOT NULL, match_session INTEGER NOT NULL, "
        "query_frame INTEGER NOT NULL, match_frame INTEGER NOT NULL, query_keyframe INTEGER NOT NULL, "
        "match_keyframe INTEGER NOT NULL, score REAL NOT NULL, n_matches INTEGER NOT NULL, "
        "relative_pose BLOB NOT NULL)"
    ),
    "objects": (
        "CREATE TABLE objects (id INTEGER PRIMARY KEY, label TEXT NOT NULL, sums BLOB NOT NULL, "
        "weight REAL NOT NULL, count INTEGER NOT NULL)"
    ),
    "object_observations": (
        "CREATE TABLE object_observations (object INTEGER NOT NULL, experience INTEGER NOT NULL, "
        "sums BLOB NOT NULL, weight REAL NOT NULL, count INTEGER NOT NULL, PRIMARY KEY (object, experience)) "
        "WITHOUT ROWID"
    ),
    "hebbian": (
        "CREATE TABLE hebbian (keyframe INTEGER PRIMARY KEY, gc_cells INTEGER NOT NULL, gc_indices BLOB NOT NULL, "
        "gc_weights BLOB NOT NULL, hd_cells INTEGER NOT NULL, hd_indices BLOB NOT NULL, hd_weights BLOB NOT NULL, "
        "gc_peak_x INTEGER NOT NULL, gc_peak_y INTEGER NOT NULL, gc_peak_z INTEGER NOT NULL, "
        "hd_peak INTEGER NOT NULL, strength REAL NOT NULL)"
    ),
    "object_vector": (
        "CREATE TABLE object_vector (position INTEGER PRIMARY KEY, name TEXT NOT NULL UNIQUE, dtype TEXT NOT NULL, "
        "shape TEXT NOT NULL, data BLOB NOT NULL)"
    ),
    "object_vector_losses": "CREATE TABLE object_vector_losses (epoch INTEGER PRIMARY KEY, loss REAL NOT NULL)",
}


ColumnInfo = tuple[object, ...]  # (name, declared type, NOT NULL, primary-key position) of one column


@cache
def format_schema() -> dict[tuple[str, str], tuple[str | None, tuple[ColumnInfo, ...]]]:
    """(type, name) -> (sql, columns) of every schema object of a map as the format makes it (its tables and the
    indexes SQLite makes for their keys), read from a database made in memory with TABLES."""
    reference = sqlite3.connect(":memory:")
    try:
        for statement in TABLES.values():
            reference.execute(statement)
        rows = reference.execute("SELECT type, name, sql FROM sqlite_master").fetchall()
        return {
            (kind, name): (sql, table_columns(reference, name) if kind == "table" else ()) for kind, name, sql in rows
        }
    finally:
        reference.close()


def table_columns(connection: sqlite3.Connection, table: str) -> tuple[ColumnInfo, ...]:
    """The columns of a table of a database, in order (see ColumnInfo)."""
    rows = connection.execute('SELECT name, type, "notnull", pk FROM pragma_table_xinfo(?)', (table,)).fetchall()
    return tuple(tuple(row) for row in rows)


@cache
def columns(table: str) -> str:
    """A table's columns by name, in the format's order, for a SELECT (a map's rows are read by column name)."""
    return ", ".join(f'"{column[0]}"' for column in format_schema()[("table", table)][1])


def encode(array: Any, dtype: np.dtype, shape: tuple[int, ...] | None = None, what: str = "array") -> bytes:
    """The array's raw little-endian bytes as `dtype`; with `shape`, an array of another shape is refused."""
    values = np.ascontiguousarray(array, dtype=dtype)
    if shape is not None and values.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, got {values.shape}")
    return values.tobytes()


def decode(blob: bytes, dtype: np.dtype, shape: tuple[int, ...], writable: bool = True) -> np.ndarray:
    """The array a BLOB holds, in native byte order: a writable copy, or a read-only view of the bytes."""
    if len(blob) != dtype.itemsize * math.prod(shape):
        raise ValueError(f"a {len(blob)}-byte value cannot hold a {dtype.str} array of shape {shape}")
    values = np.frombuffer(blob, dtype=dtype).reshape(shape)
    native = values.dtype.newbyteorder("=")
    if writable or values.dtype != native:
        values = values.astype(native)
        values.flags.writeable = writable
    return values


def decode_rows(blobs: list[bytes], dtype: np.dtype, shape: tuple[int, ...]) -> np.ndarray:
    """(n, *shape) native array from n BLOBs of one shape each (one copy, not n)."""
    size = dtype.itemsize * math.prod(shape)
    if any(len(blob) != size for blob in blobs):
        raise ValueError(f"a value is not a {dtype.str} array of shape {shape}")
    return np.frombuffer(b"".join(blobs), dtype=dtype).astype(dtype.newbyteorder("=")).reshape(len(blobs), *shape)


def config_difference(stored: Mapping[str, Any], current: Mapping[str, Any], sections: tuple[str, ...]) -> str | None:
    """The first field of `sections` whose value differs between two JSON config dumps, as a one-line description
    (`made with section.field = stored; this run has current`); None when they agree."""
    stored, current = json.loads(json.dumps(dict(stored))), json.loads(json.dumps(dict(current)))  # tuples: lists
    for section in sections:
        found = _first_difference(stored, current, section, section)
        if found is not None:
            return found
    return None


def _first_difference(stored: dict[str, Any], current: dict[str, Any], key: str, where: str) -> str | None:
    if key not in stored:
        return f"made without {where}; this run has {current[key]!r}" if key in current else None
    if key not in current:
        return f"made with {where} = {stored[key]!r}; this run has no such setting"
    old, new = stored[key], current[key]
    if isinstance(old, dict) and isinstance(new, dict):
        for inner in [*new, *(inner for inner in old if inner not in new)]:
            found = _first_difference(old, new, inner, f"{where}.{inner}")
            if found is not None:
                return found
        return None
    return None if old == new else f"made with {where} = {old!r}; this run has {new!r}"


def stored_name(name: str) -> str | bytes:
    """A session's name as the file stores it: text when it is UTF-8, else the bytes `os.fsencode` gives (a dataset
    named by a file name that is not UTF-8), so that `read_name` gives the same name back."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return name.encode("utf-8", "surrogateescape" if _escapes_only(name) else "surrogatepass")
    return name


def read_name(value: str | bytes) -> str:
    """The name `stored_name` stored: bytes that are not UTF-8 come back as the surrogate escapes os.fsdecode gives."""
    return value if isinstance(value, str) else value.decode("utf-8", "surrogateescape")


def _escapes_only(name: str) -> bool:
    return all(not 0xD800 <= ord(c) <= 0xDFFF or 0xDC80 <= ord(c) <= 0xDCFF for c in name)


# The statements a commit runs (executemany), by name.
STATEMENTS = {
    "session": "INSERT INTO sessions (id, name, frames, relocalised_frame) VALUES (?, ?, ?, ?) ON CONFLICT (id) DO "
    "UPDATE SET name = excluded.name, frames = excluded.frames, relocalised_frame = excluded.relocalised_frame",
    "keyframe": "INSERT INTO keyframes (id, frame, experience, pose, objects, centers, labels, patch_height, "
    "patch_width, patches, provisional, covariances) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
    "keyframe_experience": "UPDATE keyframes SET experience = ? WHERE id = ?",
    "experience": "INSERT INTO experiences (id, session, frame, grid_cell, head_direction, odometry_pose, "
    "linear_velocity, angular_velocity, keyframe) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
    "poses": "INSERT INTO experience_poses (block, poses) VALUES (?, ?) ON CONFLICT (block) DO UPDATE SET "
    "poses = excluded.poses",
    "link": "INSERT INTO links (id, source, target, relative, kind, distance_m, duration_s) "
    "VALUES (?, ?, ?, ?, ?, ?, ?)",
    "withdrawn_link": "INSERT INTO withdrawn_links (link) VALUES (?)",
    "closure": "INSERT INTO closures (id, session, match_session, query_frame, match_frame, query_keyframe, "
    "match_keyframe, score, n_matches, relative_pose) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
    "object": "INSERT INTO objects (id, label, sums, weight, count) VALUES (?, ?, ?, ?, ?) ON CONFLICT (id) DO "
    "UPDATE SET label = excluded.label, sums = excluded.sums, weight = excluded.weight, count = excluded.count",
    "observation": "INSERT INTO object_observations (object, experience, sums, weight, count) VALUES (?, ?, ?, ?, ?) "
    "ON CONFLICT (object, experience) DO UPDATE SET sums = excluded.sums, weight = excluded.weight, "
    "count = excluded.count",
    "observation_gone": "DELETE FROM object_observations WHERE object = ? AND experience = ?",
    "hebbian": "INSERT OR REPLACE INTO hebbian (keyframe, gc_cells, gc_indices, gc_weights, hd_cells, hd_indices, "
    "hd_weights, gc_peak_x, gc_peak_y, gc_peak_z, hd_peak, strength) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
    "hebbian_gone": "DELETE FROM hebbian WHERE keyframe = ?",
    "object_vector_cleared": "DELETE FROM object_vector",
    "object_vector": "INSERT INTO object_vector (position, name, dtype, shape, data) VALUES (?, ?, ?, ?, ?)",
    "loss": "INSERT INTO object_vector_losses (epoch, loss) VALUES (?, ?)",
}


# Records as rows


def session_row(record: SessionRecord) -> tuple[Any, ...]:
    relocalised = None if record.relocalised_frame is None else int(record.relocalised_frame)
    return int(record.id), stored_name(str(record.name)), int(record.frames), relocalised


def keyframe_row(keyframe: Keyframe, experience: int | None) -> tuple[Any, ...]:
    n = len(keyframe.labels)
    patches = np.asarray(keyframe.patches)
    height, width = patches.shape[1:] if patches.ndim == 3 else (0, 0)
    return (
        int(keyframe.id),
        int(keyframe.frame_index),
        None if experience is None else int(experience),
        encode(keyframe.pose, F8, POSE, "a keyframe pose"),
        n,
        encode(keyframe.centers, F8, (n, 3), f"keyframe {keyframe.id}'s centers"),
        json.dumps(list(keyframe.labels)),
        int(height),
        int(width),
        encode(patches, U1, (n, height, width), f"keyframe {keyframe.id}'s patches"),
        encode(np.asarray(keyframe.provisional, dtype=U1), U1, (n,), f"keyframe {keyframe.id}'s provisional flags"),
        encode(keyframe.covariances, F8, (n, 2, 2), f"keyframe {keyframe.id}'s covariances"),
    )


def experience_row(experience: Experience) -> tuple[Any, ...]:
    return (
        int(experience.id),
        int(experience.session),
        int(experience.frame_index),
        encode(experience.grid_cell, F8, VECTOR, "a grid cell"),
        float(experience.head_direction),
        encode(experience.pose, F8, POSE, "an experience pose"),
        encode(experience.linear_velocity, F8, VECTOR, "a linear velocity"),
        encode(experience.angular_velocity, F8, VECTOR, "an angular velocity"),
        None if experience.keyframe_id is None else int(experience.keyframe_id),
    )


def link_row(index: int, link: Link) -> tuple[Any, ...]:
    if link.kind not in ("odometry", "loop"):
        raise ValueError(f"link {index} is of kind {link.kind!r}, not 'odometry' or 'loop'")
    relative = encode(link.relative, F8, POSE, "a link")
    return (
        index,
        int(link.source),
        int(link.target),
        relative,
        link.kind,
        float(link.distance_m),
        float(link.duration_s),
    )


def closure_row(index: int, stored: StoredClosure) -> tuple[Any, ...]:
    closure = stored.closure
    return (
        index,
        int(stored.session),
        int(stored.match_session),
        int(closure.query_frame),
        int(closure.match_frame),
        int(closure.query_keyframe),
        int(closure.match_keyframe),
        float(closure.score),
        int(closure.n_matches),
        encode(closure.relative_pose, F8, POSE, "a closure's relative pose"),
    )


def hebbian_row(keyframe_id: int, trace: HebbianTrace) -> tuple[Any, ...]:
    gc_n, hd_n = len(trace.gc_indices), len(trace.hd_indices)
    x, y, z = (int(cell) for cell in trace.gc_peak)
    return (
        int(keyframe_id),
        gc_n,
        encode(trace.gc_indices, I4, (gc_n,)),
        encode(trace.gc_weights, F4, (gc_n,), f"keyframe {keyframe_id}'s grid-cell weights"),
        hd_n,
        encode(trace.hd_indices, I4, (hd_n,)),
        encode(trace.hd_weights, F4, (hd_n,), f"keyframe {keyframe_id}'s head-direction weights"),
        x,
        y,
        z,
        int(trace.hd_peak),
        float(trace.strength),
    )
