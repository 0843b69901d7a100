"""The sweep's tables: one row per cell (CSV and Parquet), its timing apart, and a markdown summary of medians and
ranges by chosen columns.

The row table holds only what a cell computes (labels, status, error, metrics): wall times, frame rates, host and
process go to the timing table, so that the row table has the same bytes wherever and however fast a cell ran."""

from __future__ import annotations

import csv
import io
import math
import statistics
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from neoslam.io.atomic import atomic_file
from neoslam.sweep.spec import AXES

__all__ = ["LABEL_COLUMNS", "flatten", "split_timing", "columns_of", "write_tables", "summary_markdown"]

LABEL_COLUMNS = ("cell", *AXES, "status", "error")
TIMING_PREFIXES = ("timing.", "perception.")  # metrics that depend on the machine, not on the inputs
TIMING_LABELS = ("cell", *AXES)


def flatten(metrics: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested metrics as dotted scalar columns; lists and keys starting with "_" (a measure's own detail) are left
    in metrics.json."""
    flat: dict[str, Any] = {}
    for key, value in metrics.items():
        if str(key).startswith("_"):
            continue
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat |= flatten(value, f"{name}.")
        elif value is None or isinstance(value, bool | int | float | str):
            flat[name] = value
    return flat


def split_timing(flat: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(what a cell computes, what depends on the machine)."""
    timing = {k: v for k, v in flat.items() if k.startswith(TIMING_PREFIXES)}
    return {k: v for k, v in flat.items() if k not in timing}, timing


def columns_of(rows: Iterable[Mapping[str, Any]], first: Iterable[str]) -> list[str]:
    """`first`, then every other column in the order rows first show it."""
    columns = dict.fromkeys(first)
    for row in rows:
        columns |= dict.fromkeys(row)
    return list(columns)


def _csv_value(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value).lower()
    return str(value)


def _csv(rows: list[dict[str, Any]], columns: list[str]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_csv_value(row.get(c)) for c in columns])
    return buffer.getvalue()


def _arrow_column(values: list[Any]) -> Any:
    """One typed column: bool, int64, float64 or string, whatever mix of values (and gaps) the rows hold."""
    import pyarrow as pa

    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return pa.array(values, pa.bool_())
    if present and all(isinstance(v, int) and not isinstance(v, bool) for v in present):
        return pa.array(values, pa.int64())
    if present and all(isinstance(v, int | float) and not isinstance(v, bool) for v in present):
        return pa.array([None if v is None else float(v) for v in values], pa.float64())
    return pa.array([None if v is None else _csv_value(v) for v in values], pa.string())


def _write_parquet(path: Path, rows: list[dict[str, Any]], columns: list[str]) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({c: _arrow_column([row.get(c) for row in rows]) for c in columns})
    pq.write_table(table, path, compression="zstd")


def _number(value: float) -> str:
    if value.is_integer() and abs(value) < 1e6:
        return str(int(value))
    if 0.01 <= abs(value) < 1e5:
        return f"{value:.3f}" if abs(value) < 100 else f"{value:.1f}"
    return f"{value:.3g}"


def _median_range(values: list[Any]) -> str:
    numbers = [float(v) for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    numbers = [v for v in numbers if math.isfinite(v)]
    if not numbers:
        return "–"
    low, middle, high = min(numbers), statistics.median(numbers), max(numbers)
    if low == high:
        return _number(middle)
    return f"{_number(middle)} ({_number(low)} – {_number(high)})"


def summary_markdown(
    title: str, rows: list[dict[str, Any]], columns: list[str], metrics: list[str], note: str = ""
) -> str:
    """Per group of `columns`: the cells, the failed ones, and each metric's median (min – max) over the cells
    that succeeded."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row.get(c) for c in columns), []).append(row)
    header = [*columns, "cells", "failed", *metrics]
    lines = [f"# {title}", ""]
    if note:
        lines += [note, ""]
    lines += ["Median (min – max) over the cells of each group.", ""]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, members in groups.items():
        good = [r for r in members if r.get("status") == "ok"]
        cells = [_csv_value(v) if v is not None else "–" for v in key]
        cells += [str(len(members)), str(len(members) - len(good))]
        cells += [_median_range([r.get(m) for r in good]) for m in metrics]
        lines.append("| " + " | ".join(cells) + " |")
    failed = [r for r in rows if r.get("status") != "ok"]
    if failed:
        lines += ["", "Failed cells:", ""]
        lines += [f"- {r['cell']} ({', '.join(str(r.get(a)) for a in AXES if r.get(a) is not None)}): "
                  f"{r.get('error')}" for r in failed]  # fmt: skip
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> None:
    with atomic_file(path, overwrite=True) as staging:
        staging.write_text(text)


def write_tables(
    folder: Path,
    rows: list[dict[str, Any]],
    timing: list[dict[str, Any]],
    summary: str,
) -> dict[str, Path]:
    """sweep.csv, sweep.parquet, timing.csv and summary.md in the folder, each replaced whole."""
    columns = columns_of(rows, LABEL_COLUMNS)
    timing_columns = columns_of(timing, TIMING_LABELS)
    paths = {
        "csv": folder / "sweep.csv",
        "parquet": folder / "sweep.parquet",
        "timing": folder / "timing.csv",
        "summary": folder / "summary.md",
    }
    _write_text(paths["csv"], _csv(rows, columns))
    with atomic_file(paths["parquet"], overwrite=True) as staging:
        _write_parquet(staging, rows, columns)
    _write_text(paths["timing"], _csv(timing, timing_columns))
    _write_text(paths["summary"], summary)
    return paths
