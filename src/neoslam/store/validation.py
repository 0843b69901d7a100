"""Whether a file is a NeoSLAM map this run may open (see neoslam.store.map_file): the file header, checked before
connecting, then the meta table, the tables and the config, checked on a connection. Every refusal is an InputError
naming one problem; nothing here writes to the file.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

from neoslam import __version__
from neoslam.config import MAP_SECTIONS, NeoSLAMConfig
from neoslam.errors import InputError
from neoslam.store.schema import APPLICATION_ID, FORMAT_TAG, FORMAT_VERSION, TABLES, config_difference

__all__ = ["MAP_SECTIONS", "read_header", "validate", "locked"]


_SQLITE_MAGIC = b"SQLite format 3\x00"
_HEADER_SIZE = 100
_EXTENDED = "a map is extended with the config it was made with"


def read_header(path: Path) -> bytes:
    """The file's first 100 bytes, once it is a regular file with SQLite's header and NeoSLAM's application id
    (read before connecting: another program's database is refused without being opened, let alone copied)."""
    if not path.exists():
        raise InputError(path, "map not found")
    if path.is_dir():
        raise InputError(path, "a folder, not a NeoSLAM map file")
    if not path.is_file():
        raise InputError(path, "not a regular file, so not a NeoSLAM map")
    try:
        with path.open("rb") as file:
            header = file.read(_HEADER_SIZE)
    except OSError as error:
        raise InputError(path, f"cannot be read ({error.strerror})") from None
    if not header:
        raise InputError(path, "empty file, not a NeoSLAM map")
    if header[: len(_SQLITE_MAGIC)] != _SQLITE_MAGIC[: len(header)]:
        raise InputError(path, "not a SQLite file, so not a NeoSLAM map")
    if len(header) < _HEADER_SIZE:
        raise InputError(path, f"corrupt map file (truncated to {len(header)} bytes)")
    if int.from_bytes(header[68:72], "big") != APPLICATION_ID:  # set when the map is made, never changed
        raise InputError(path, "a SQLite database but not a NeoSLAM map")
    return header


def validate(connection: sqlite3.Connection, path: Path, config: NeoSLAMConfig) -> None:
    """Refuse (InputError, one problem) a file that is not a map this run may extend."""
    try:
        tables = {name for (name,) in connection.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        try:
            meta = dict(connection.execute("SELECT key, value FROM meta")) if "meta" in tables else {}
        except sqlite3.OperationalError as error:
            if locked(error):
                raise
            meta = {}  # a table `meta` of another kind
        if meta.get("format") != FORMAT_TAG:
            raise InputError(path, "a SQLite database but not a NeoSLAM map")
        if meta.get("format_version") != str(FORMAT_VERSION):
            raise InputError(
                path, f"map format version {meta.get('format_version')}; this NeoSLAM reads version {FORMAT_VERSION}"
            )
        missing = [table for table in TABLES if table not in tables]
        if missing:
            raise InputError(path, f"corrupt map file (no table {missing[0]})")
        if meta.get("neoslam_version") != __version__:
            raise InputError(
                path,
                f"made by NeoSLAM {meta.get('neoslam_version')}; this is NeoSLAM {__version__} (a map is read and "
                "extended by the version that made it)",
            )
        try:
            stored = json.loads(meta["config"])
        except (KeyError, ValueError) as error:
            raise InputError(path, f"corrupt map file (its config: {error})") from None
        if not isinstance(stored, dict):
            raise InputError(path, "corrupt map file (its config is not a mapping)")
        difference = config_difference(stored, config.model_dump(mode="json"), MAP_SECTIONS)
        if difference is not None:
            raise InputError(path, f"{difference} ({_EXTENDED})")
        problems = [row[0] for row in connection.execute("PRAGMA quick_check")]
        if problems != ["ok"]:
            raise InputError(path, f"corrupt map file ({problems[0]})")
    except sqlite3.DatabaseError as error:
        if locked(error):
            raise InputError(path, "in use by another run (the map file is locked)") from None
        raise InputError(path, f"corrupt map file ({error})") from None


def locked(error: sqlite3.Error) -> bool:
    """Whether SQLite refused because another connection holds the file (a run writing the map)."""
    return isinstance(error, sqlite3.OperationalError) and "locked" in str(error)
