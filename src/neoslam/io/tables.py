"""Small CSV tables with a header row: read with one precise error per problem, write deterministically."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from neoslam.errors import InputError
from neoslam.text import read_text

__all__ = ["read_table", "write_table", "numeric_column"]


def read_table(path: Path, columns: Sequence[str]) -> list[list[str]]:
    """Rows (lists of strings) of a CSV file whose header is exactly `columns`."""
    reader = csv.reader(io.StringIO(read_text(path), newline=""))
    try:
        rows = [row for row in reader if row]  # blank lines carry nothing
    except csv.Error as error:  # a NUL byte, a field over csv's size limit
        raise InputError(path, f"not a CSV table ({error})", line=reader.line_num) from None
    if not rows:
        raise InputError(path, f"empty file: expected the header {','.join(columns)}", line=1)
    if [name.strip() for name in rows[0]] != list(columns):
        raise InputError(path, f"header is {','.join(rows[0])!r}, expected {','.join(columns)!r}", line=1)
    body = rows[1:]
    for number, row in enumerate(body, start=2):
        if len(row) != len(columns):
            raise InputError(path, f"{len(row)} columns, expected {len(columns)}", line=number)
    return body


def numeric_column(path: Path, rows: list[list[str]], columns: Sequence[str], name: str) -> np.ndarray:
    """One column as floats; a non-number, NaN or inf names its line."""
    index = list(columns).index(name)
    values = np.empty(len(rows))
    for number, row in enumerate(rows, start=2):
        token = row[index].strip()
        try:
            value = float(token)
        except ValueError:
            raise InputError(path, f"column {name}: {token!r} is not a number", line=number) from None
        if not math.isfinite(value):
            raise InputError(path, f"column {name}: {token} is not finite", line=number)
        values[number - 2] = value
    return values


def write_table(path: Path, columns: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Write a CSV file; floats must already be formatted by the caller for byte-stable output."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(rows)
