"""CSV tables with a header row: one precise InputError per problem, naming the file and the line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from neoslam.errors import InputError
from neoslam.io.tables import numeric_column, read_table, write_table

COLUMNS = ("frame", "label", "x")


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "table.csv"
    path.write_text(text)
    return path


def test_write_then_read(tmp_path: Path) -> None:
    path = tmp_path / "out.csv"
    write_table(path, COLUMNS, [[0, "car", "1.5000"], [1, "a, b", "-2"]])
    assert path.read_bytes() == b'frame,label,x\n0,car,1.5000\n1,"a, b",-2\n'
    table = read_table(path, COLUMNS)
    assert table.rows == [["0", "car", "1.5000"], ["1", "a, b", "-2"]]
    assert table.lines.tolist() == [2, 3]
    np.testing.assert_array_equal(numeric_column(path, table, COLUMNS, "x"), [1.5, -2.0])


def test_header_only_gives_no_rows(tmp_path: Path) -> None:
    path = _write(tmp_path, "frame,label,x\n")
    table = read_table(path, COLUMNS)
    assert table.rows == []
    assert numeric_column(path, table, COLUMNS, "x").shape == (0,)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError) as caught:
        read_table(tmp_path / "absent.csv", COLUMNS)
    assert caught.value.path == tmp_path / "absent.csv"


def test_empty_file(tmp_path: Path) -> None:
    path = _write(tmp_path, "")
    with pytest.raises(InputError) as caught:
        read_table(path, COLUMNS)
    assert (caught.value.path, caught.value.line) == (path, 1)


def test_header_mismatch(tmp_path: Path) -> None:
    path = _write(tmp_path, "frame,name,x\n0,car,1\n")
    with pytest.raises(InputError, match="header") as caught:
        read_table(path, COLUMNS)
    assert (caught.value.path, caught.value.line) == (path, 1)
    assert f"{path}:1:" in str(caught.value)


def test_blank_lines_count_in_the_line_named(tmp_path: Path) -> None:
    path = _write(tmp_path, "\nframe,label,x\n\n0,car,1\n\n\n1,car,oops\n")
    table = read_table(path, COLUMNS)
    assert table.lines.tolist() == [4, 7]
    with pytest.raises(InputError, match="not a number") as caught:
        numeric_column(path, table, COLUMNS, "x")
    assert caught.value.line == 7


def test_wrong_column_count(tmp_path: Path) -> None:
    path = _write(tmp_path, "frame,label,x\n0,car,1\n1,car\n")
    with pytest.raises(InputError, match="2 columns, expected 3") as caught:
        read_table(path, COLUMNS)
    assert (caught.value.path, caught.value.line) == (path, 3)
    assert f"{path}:3:" in str(caught.value)


@pytest.mark.parametrize(
    ("token", "problem"),
    [("abc", "not a number"), ("", "not a number"), ("nan", "not finite"), ("NaN", "not finite"), ("inf", "finite")],
)
def test_bad_number_names_file_and_line(tmp_path: Path, token: str, problem: str) -> None:
    path = _write(tmp_path, f"frame,label,x\n0,car,1\n1,car,2\n2,car,{token}\n")
    rows = read_table(path, COLUMNS)
    with pytest.raises(InputError, match=problem) as caught:
        numeric_column(path, rows, COLUMNS, "x")
    assert (caught.value.path, caught.value.line) == (path, 4)
    assert "column x" in str(caught.value)
