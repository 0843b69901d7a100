"""A sweep folder damaged between runs: a finished cell whose files do not read back runs again (a line names the
file) while the rest is reused; a file or folder where the sweep writes something else is refused before any work."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from neoslam.errors import OutputError
from neoslam.sweep import InProcess, parse_spec, run_sweep

SPEC = {"name": "damaged", "sources": [{"route": "block", "frames": 20}], "seeds": [1, 2, 3, 4, 5], "metrics": ["x"]}


def measure(dataset: Path, config, out: Path, inputs) -> dict:
    """A cell in milliseconds: the simulated dataset's seed back, and a nested block."""
    return {"x": config.simulator.seed, "nested": {"y": config.simulator.seed * 2}}


class Counting(InProcess):
    def __init__(self) -> None:
        self.cells: list[str] = []

    def run(self, tasks, done) -> None:
        self.cells += [c.id for t in tasks for c in t.cells]
        super().run(tasks, done)


@pytest.fixture
def finished(tmp_path: Path) -> tuple[Path, dict[str, bytes], list[str]]:
    """A finished 5-cell sweep: its folder, its tables' bytes, its cells in the spec's order."""
    out = tmp_path / "sweep"
    result = run_sweep(_spec(tmp_path), out, InProcess(), progress=False, measure=measure, environ={})
    tables = {name: (out / name).read_bytes() for name in ("sweep.csv", "sweep.parquet", "summary.md")}
    return out, tables, [r.cell.id for r in result.records]


def _spec(tmp_path: Path):
    return parse_spec(SPEC, "damaged.yaml", tmp_path)


def _resume(tmp_path: Path, out: Path) -> tuple[Counting, list[str], object]:
    executor, lines = Counting(), []
    result = run_sweep(_spec(tmp_path), out, executor, False, measure, {}, notice=lines.append)
    return executor, lines, result


def test_damaged_cells_run_again_and_the_rest_is_reused(tmp_path: Path, finished) -> None:
    out, tables, ids = finished
    cells = out / "cells"
    (cells / ids[0] / "metrics.json").write_text('{"x": 1, "nest')  # cut short
    (cells / ids[1] / "metrics.json").write_text("[1, 2]\n")  # JSON, not what a cell writes
    (cells / ids[2] / "timing.json").write_bytes(b"\xff\xfe")  # not text
    (cells / ids[3] / "metrics.json").unlink()
    (cells / ids[3] / "metrics.json").mkdir()  # not a file
    executor, lines, result = _resume(tmp_path, out)
    assert executor.cells == ids[:4]  # the fifth is reused
    assert lines == [
        f"{cells / ids[0] / 'metrics.json'}: not valid JSON (Unterminated string starting at, line 1 column 10); "
        "running the cell again",
        f"{cells / ids[1] / 'metrics.json'}: holds a JSON list, not an object; running the cell again",
        f"{cells / ids[2] / 'timing.json'}: not text (not UTF-8); running the cell again",
        f"{cells / ids[3] / 'metrics.json'}: cannot be read (Is a directory); running the cell again",
    ]
    assert result.notices == lines and (result.ran, result.reused) == (4, 1)
    for name, data in tables.items():
        assert (out / name).read_bytes() == data, name
    assert json.loads((cells / ids[1] / "metrics.json").read_text()) == {"x": 2, "nested": {"y": 4}}
    assert not list(cells.glob(".*"))  # no staging or replaced folder left
    again, lines, _ = _resume(tmp_path, out)
    assert again.cells == [] and lines == []


def test_a_file_where_a_cell_folder_goes_is_replaced_by_the_cell(tmp_path: Path, finished) -> None:
    out, tables, ids = finished
    cell = out / "cells" / ids[2]
    for path in sorted(cell.iterdir()):
        path.unlink()
    cell.rmdir()
    cell.write_text("not a cell\n")
    executor, lines, _ = _resume(tmp_path, out)
    assert executor.cells == [ids[2]] and lines == [f"{cell}: is not a cell folder; running the cell again"]
    assert (cell / "metrics.json").is_file() and (out / "sweep.csv").read_bytes() == tables["sweep.csv"]


def test_a_link_where_a_cell_folder_goes_is_not_followed(tmp_path: Path, finished) -> None:
    out, tables, ids = finished
    elsewhere = tmp_path / "elsewhere"
    (out / "cells" / ids[0]).rename(elsewhere)
    (out / "cells" / ids[0]).symlink_to(elsewhere)
    executor, lines, _ = _resume(tmp_path, out)
    assert executor.cells == [ids[0]] and lines == [
        f"{out / 'cells' / ids[0]}: is not a cell folder; running the cell again"
    ]
    assert not (out / "cells" / ids[0]).is_symlink() and (elsewhere / "metrics.json").is_file()  # left as it was
    assert (out / "sweep.csv").read_bytes() == tables["sweep.csv"]


@pytest.mark.parametrize(
    ("name", "make", "problem"),
    [
        ("sweep.csv", Path.mkdir, "is a folder, not the sweep's file"),
        ("summary.md", Path.mkdir, "is a folder, not the sweep's file"),
        ("cells", None, "is not a folder, so it holds no cells"),
    ],
)
def test_a_folder_where_a_table_goes_is_refused_before_any_work(tmp_path: Path, finished, name, make, problem) -> None:
    out, _, ids = finished
    target = out / name
    if target.is_dir():
        for cell in target.iterdir():
            for path in cell.iterdir():
                path.unlink()
            cell.rmdir()
        target.rmdir()
    else:
        target.unlink()
    if make is None:
        target.write_text("a file\n")
    else:
        make(target)
    executor = Counting()
    with pytest.raises(OutputError) as caught:
        run_sweep(_spec(tmp_path), out, executor, False, measure, {})
    assert str(caught.value) == f"{target}: {problem}; move it away or name another folder"
    assert executor.cells == []
