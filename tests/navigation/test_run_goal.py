"""`neoslam run --map M.db --localise-only --goal ...`: guidance written per frame, its summary in metrics.json."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from neoslam.navigation.session import GUIDANCE_COLUMNS

pytestmark = pytest.mark.slow  # two runs of a simulated drive


def test_a_run_on_a_stored_map_is_guided_to_its_start(cli, block_seed5: Path, tmp_path: Path) -> None:
    map_file = tmp_path / "block.db"
    cli.ok("run", block_seed5, "--map", map_file, "--out", tmp_path / "first", "--quiet")
    before = map_file.read_bytes()
    result = cli.ok("run", block_seed5, "--map", map_file, "--localise-only", "--goal", "start of session 1",
                    "--out", tmp_path / "guided", "--quiet")  # fmt: skip
    assert map_file.read_bytes() == before  # localise-only: the map is used, not changed
    with (tmp_path / "guided" / "guidance.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == GUIDANCE_COLUMNS
    states = [row["state"] for row in rows]
    assert states[0] == "not_localised" and "unreachable" not in states
    assert {"on_route", "replanned", "arrived"} & set(states)
    guidance = json.loads((tmp_path / "guided" / "metrics.json").read_text())["guidance"]
    assert guidance["goal"] == "start of session 1" and guidance["localised_frame"] is not None
    assert "goal" in result.stdout


def test_a_goal_that_does_not_parse_is_refused_before_the_run(cli, block_seed5: Path, tmp_path: Path) -> None:
    result = cli.invoke("run", block_seed5, "--goal", "the moon", "--out", tmp_path / "r", "--quiet")
    cli.one_line_error(result, "the moon")
    assert not (tmp_path / "r").exists()
