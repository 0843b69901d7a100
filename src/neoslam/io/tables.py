"""Small CSV tables with a header row: read with one precise error per problem, write deterministically."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from neoslam.errors import InputError
from neoslam.text import read_text

__all__ = ["Table", "read_table", "write_table", "numeric_column"]


@dataclass(frozen=True)
class Table:
    """A CSV table's rows below its header (lists of strings) and the file line of each, blank lines skipped."""

    rows: list[list[str]]
    lines: np.ndarray  # (n,) int

    def __len__(self) -> int:
        return len(self.rows)


def read_table(path: Path, columns: Sequence[str]) -> Table:
    """The rows of a CSV file whose header is exactly `columns`, each with its line in the file."""
    reader = csv.reader(io.StringIO(read_text(path), newline=""))
    rows, lines = [], []
    try:
        for row in reader:
            if row:  # blank lines carry nothing, but count as lines of the file
                rows.append(row)
                lines.append(reader.line_num)
    except csv.Error as error:  # a NUL byte, a field over csv's size limit
        raise InputError(path, f"not a CSV table ({error})", line=reader.line_num) from None
    if not rows:
        raise InputError(path, f"empty file: expected the header {','.join(columns)}", line=1)
    if [name.strip() for name in rows[0]] != list(columns):
        raise InputError(path, f"header is {','.join(rows[0])!r}, expected {','.join(columns)!r}", line=lines[0])
    table = Table(rows[1:], np.array(lines[1:], dtype=int))
    for row, line in zip(table.rows, table.lines, strict=True):
        if len(row) != len(columns):
            raise InputError(path, f"{len(row)} columns, expected {len(columns)}", line=int(line))
    return table


def numeric_column(path: Path, table: Table, columns: Sequence[str], name: str) -> np.ndarray:
    """One column as floats; a non-number, NaN or inf names its line."""
    index = list(columns).index(name)
    values = np.empty(len(table))
    for k, (row, line) in enumerate(zip(table.rows, table.lines, strict=True)):
        token = row[index].strip()
        try:
            value = float(token)
        except ValueError:
            raise InputError(path, f"column {name}: {token!r} is not a number", line=int(line)) from None
        if not math.isfinite(value):
            raise InputError(path, f"column {name}: {token} is not finite", line=int(line))
        values[k] = value
    return values


def write_table(path: Path, columns: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
    """Write a CSV file; floats must already be formatted by the caller for byte-stable output."""
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(columns)
        writer.writerows(rows)
