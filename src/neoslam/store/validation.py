"""Whether a file is a NeoSLAM map this run may open (see neoslam.store.map_file): the file header, checked before
connecting, then the meta table, the schema, the version and the config, checked on a connection. Every refusal is
an InputError naming one problem; nothing here writes to the file.

A map is a file users pass around, so it is untrusted input: a trigger in it would run its own SQL at the first
commit (deleting keyframes, or looping for ever), a view or an index could be made to do the same on reading, and a
table rebuilt with its columns in another order would be read wrongly. The schema must be exactly the format's: no
trigger, view, index or table the format does not define, and every table's columns in the format's names, types,
constraints and order (`check_schema`); the connections run with `trusted_schema` off (neoslam.store.map_file).
"""

from __future__ import annotations

import json
import os
import sqlite3
import stat
from contextlib import suppress
from pathlib import Path

from neoslam import __version__
from neoslam.config import MAP_SECTIONS, NeoSLAMConfig
from neoslam.errors import InputError
from neoslam.store.reading import first_line
from neoslam.store.schema import (
    APPLICATION_ID,
    FORMAT_TAG,
    FORMAT_VERSION,
    TABLES,
    ColumnInfo,
    config_difference,
    format_schema,
    table_columns,
)

__all__ = ["MAP_SECTIONS", "check_schema", "interrupted", "locked", "read_header", "validate"]


_SQLITE_MAGIC = b"SQLite format 3\x00"
_NAME_CHARS = 60  # a schema object's name is clipped to this in a message (a file may give it any length)
_HEADER_SIZE = 100
_EXTENDED = "a map is extended with the config it was made with"


def read_header(path: Path) -> bytes:
    """The file's first 100 bytes, once it is a regular file with SQLite's header, NeoSLAM's application id and
    this format version as its user_version, small enough to load (read before connecting: another program's
    database is refused without being opened, let alone copied). A FIFO or a device (or a link to one) is refused
    without being read: it is opened without blocking and checked again once open."""
    try:
        kind = _kind(os.stat(path).st_mode)
    except FileNotFoundError:
        raise InputError(path, "map not found") from None
    except OSError as error:
        raise InputError(path, f"cannot be read ({error.strerror})") from None
    if kind == "a folder":
        raise InputError(path, "a folder, not a NeoSLAM map file")
    if kind is not None:
        raise InputError(path, f"{kind}, not a regular file, so not a NeoSLAM map")
    try:
        descriptor = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except OSError as error:
        raise InputError(path, f"cannot be read ({error.strerror})") from None
    try:
        status = os.fstat(descriptor)
        kind = _kind(status.st_mode)  # replaced by another kind of file since the first look
        if kind is not None:
            raise InputError(path, f"{kind}, not a regular file, so not a NeoSLAM map")
        header = os.read(descriptor, _HEADER_SIZE)
    except OSError as error:
        raise InputError(path, f"cannot be read ({error.strerror})") from None
    finally:
        os.close(descriptor)
    if not header:
        raise InputError(path, "empty file, not a NeoSLAM map")
    if header[: len(_SQLITE_MAGIC)] != _SQLITE_MAGIC[: len(header)]:
        raise InputError(path, "not a SQLite file, so not a NeoSLAM map")
    if len(header) < _HEADER_SIZE:
        raise InputError(path, f"corrupt map file (truncated to {len(header)} bytes)")
    if int.from_bytes(header[68:72], "big") != APPLICATION_ID:  # set when the map is made, never changed
        raise InputError(path, "a SQLite database but not a NeoSLAM map")
    user_version = int.from_bytes(header[60:64], "big", signed=True)  # the format version, set when it is made
    if user_version <= 0:  # never set: SQLite's default, so another program's database with the same id
        raise InputError(
            path,
            f"a SQLite database but not a NeoSLAM map (its header's user_version is {user_version}; a map's is its "
            f"format version, {FORMAT_VERSION})",
        )
    if user_version != FORMAT_VERSION:
        newer = " (a newer NeoSLAM's)" if user_version > FORMAT_VERSION else ""
        raise InputError(
            path,
            f"map format version {user_version}{newer} in its header's user_version; this NeoSLAM reads version "
            f"{FORMAT_VERSION}",
        )
    _check_size(path, status.st_size)
    return header


def _kind(mode: int) -> str | None:
    """What a file that is not a regular file is (None: a regular file)."""
    if stat.S_ISREG(mode):
        return None
    for test, kind in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a named pipe (FIFO)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return kind
    return "a special file"


def _check_size(path: Path, size: int) -> None:
    """Refuse a map larger than this machine's memory: loading reads it whole (its arrays take about the room they
    take in the file), and a map too large would be killed half-loaded rather than refused."""
    with suppress(FileNotFoundError):
        size += os.stat(f"{path}-wal").st_size  # a run killed while writing: its log is read too
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not known here: nothing to compare with
        return
    if memory > 0 and size > memory:
        raise InputError(path, f"too large to load ({_size(size)}; this machine has {_size(memory)} of memory)")


def _size(count: int) -> str:
    return f"{count / 2**30:.1f} GiB" if count >= 2**30 else f"{count / 2**20:.1f} MiB"


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
        check_schema(connection, path)
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
    except sqlite3.Error as error:
        if interrupted(error):
            raise KeyboardInterrupt from None
        if locked(error):
            raise InputError(path, "in use by another run (the map file is locked)") from None
        raise InputError(path, f"corrupt map file ({first_line(str(error))})") from None


def check_schema(connection: sqlite3.Connection, path: Path) -> None:
    """Refuse a schema that is not exactly the format's: an object it does not define (trigger, view, index, table),
    or a table whose columns (name, type, NOT NULL, primary key, order) or definition differ."""
    expected = format_schema()
    found = connection.execute("SELECT type, name, tbl_name, sql FROM sqlite_master ORDER BY rowid").fetchall()
    for kind, name, table, sql in found:
        if (kind, name) not in expected:
            where = "" if kind == "table" or name == table else f" on table {_clipped(table)}"
            article = "an" if kind[0] in "aeiou" else "a"
            raise InputError(
                path,
                f"{article} {kind} {_clipped(name)}{where} that the map format does not define (a map holds only the "
                "format's tables: one given with more could run its own SQL when it is written to)",
            )
        if kind == "table":
            columns, wanted = table_columns(connection, name), expected[(kind, name)][1]
            if [column[0] for column in columns] != [column[0] for column in wanted]:
                raise InputError(
                    path, f"table {name}: columns {_listed(columns)} differ from the format's {_listed(wanted)}"
                )
            for column, format_column in zip(columns, wanted, strict=True):
                if column != format_column:
                    raise InputError(
                        path,
                        f"table {name}: columns ({_clipped(column[0])} is {_declared(column)}) differ in type or "
                        f"constraint from the format's ({_declared(format_column)})",
                    )
        if sql != expected[(kind, name)][0]:
            what = "" if kind == "table" else f"its {kind} {_clipped(name)} "
            raise InputError(path, f"table {table}: {what}defined otherwise than the format's (its constraints)")


def _declared(column: ColumnInfo) -> str:
    _, kind, not_null, key = column
    return " ".join(
        str(part) for part in (kind or "untyped", "NOT NULL" if not_null else "", "PRIMARY KEY" if key else "") if part
    )


def _listed(columns: tuple[ColumnInfo, ...]) -> str:
    names = ", ".join(_clipped(str(column[0])) for column in columns[:20])
    more = f", and {len(columns) - 20} more" if len(columns) > 20 else ""
    return f"({names}{more})"


def _clipped(name: object) -> str:
    text = repr(str(name))
    return text if len(text) <= _NAME_CHARS else f"{text[: _NAME_CHARS - 4]}...'"


def interrupted(error: BaseException) -> bool:
    """Whether SQLite stopped a statement because a signal arrived while it ran (a progress handler's turn:
    neoslam.store.map_file): Ctrl-C, which must stop the run, not read as a damaged file."""
    return isinstance(error, sqlite3.OperationalError) and str(error) == "interrupted"


def locked(error: sqlite3.Error) -> bool:
    """Whether SQLite refused because another connection holds the file (a run writing the map)."""
    return isinstance(error, sqlite3.OperationalError) and "locked" in str(error)
