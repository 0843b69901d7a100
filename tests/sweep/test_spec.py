"""The sweep spec: its YAML form, and one line naming the spec file and the field for every mistake."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from neoslam.cli import app
from neoslam.sweep import SpecError, expand, load_spec, parse_spec

GOOD = """\
name: tiny
sources:
  - route: block
    frames: 200
  - kitti: [00, 05]
noise: [vo, heavy]
seeds: [1, 2]
overrides:
  pose_graph:
  relaxation: {experience_map: {backend: relaxation}}
columns: [source, noise]
"""


def _spec(tmp_path: Path, text: str, name: str = "spec.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _problem(tmp_path: Path, text: str, data_root: Path | None = None) -> str:
    """The one-line message of a bad spec, found by reading it or by expanding it (files, profiles, overrides)."""
    path = _spec(tmp_path, text)
    with pytest.raises(SpecError) as caught:
        spec = load_spec(path)
        if data_root is not None:
            spec = spec.model_copy(update={"data_root": data_root})
        expand(spec, environ={})
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith(f"{path}: ")
    return message.removeprefix(f"{path}: ")


def test_good_spec_reads(tmp_path: Path) -> None:
    spec = load_spec(_spec(tmp_path, GOOD))
    assert spec.name == "tiny"
    assert spec.sources[1].kitti == ["00", "05"]  # YAML's numbers 0 and 5 given back their two digits
    assert spec.overrides == {"pose_graph": {}, "relaxation": {"experience_map": {"backend": "relaxation"}}}
    assert spec.detectors == ["real"] and spec.keep_results is False
    assert spec.base_dir == tmp_path


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("name: x\nsources: [{kiti: '05'}]\n", "sources[0].kiti: unknown field"),
        ("name: x\nsources: [{kitti: '05', route: block}]\n", "sources[0]: give exactly one of kitti"),
        ("name: x\nsources: [{route: block, format: tum}]\n", "sources[0]: format: applies to trajectory sources"),
        ("name: x\nsources: []\n", "sources: List should have at least 1 item"),
        ("sources: [{route: block}]\n", "name: Field required"),
        ("name: x\nsources: [{route: block}]\nseeds: [1, 2, 1]\n", "seeds: each value once (1 is given twice)"),
        ("name: x\nsources: [{route: block}]\ncolumns: [speed]\n", "columns: 'speed' is not an axis"),
        ("name: x\nsources: [{route: block}]\nbogus: 1\n", "bogus: unknown field"),
        ("name: x\nsources: [{route: block, frames: 0}]\n", "sources[0].frames: Input should be greater than 1"),
        ("- a\n- b\n", "a sweep spec must be a mapping"),
        ("name: [x\n", "line 2: not valid YAML"),
        ("name: x\nsources: " + "[" * 50000 + "]" * 50000 + "\n", "not valid YAML (nested too deeply)"),
    ],
)
def test_spec_mistakes_are_one_line(tmp_path: Path, text: str, expected: str) -> None:
    assert _problem(tmp_path, text).startswith(expected)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (
            "overrides: {fast: {experience_map: {corection_factor: 0.3}}}",
            "overrides.fast.experience_map.corection_factor: unknown setting",
        ),
        (
            "overrides: {fast: {experience_map: {correction_factor: 5}}}",
            "overrides.fast.experience_map.correction_factor: Input should be less than or equal to 1",
        ),
        ("noise: [vo, loud]", "noise[1]: unknown noise profile 'loud'"),
        ("detectors: [perfect]", "detectors[0]: unknown detection profile 'perfect'"),
        ("cells: [{source: nowhere}]", "cells[0].source: no source named 'nowhere'"),
        ("cells: [{source: block, seed: 9}]", "cells[0].seed: 9 is not in the spec's list [1]"),
        ("config: missing.yaml", "config: file not found:"),
        ("config: .", "config: is a folder, not a file:"),
        ("seeds: [3, -1]", "seeds[1]: Input should be greater than or equal to 0 (got -1)"),
        ("metrics: [keyframes, loops.recall, ate_rsme]", "metrics[2]: unknown metric 'ate_rsme'; known: frames, "),
        ("metrics: [experience_map.backend]", "metrics[0]: unknown metric 'experience_map.backend'"),  # not a number
        ("metrics: [timing.fps]", "metrics[0]: unknown metric 'timing.fps'"),  # the machine's: not in the table
    ],
)
def test_expansion_mistakes_are_one_line(tmp_path: Path, text: str, expected: str) -> None:
    assert _problem(tmp_path, f"name: x\nsources: [{{route: block}}]\n{text}\n").startswith(expected)


def test_missing_sources_name_the_field(tmp_path: Path) -> None:
    message = _problem(tmp_path, "name: x\nsources: [{route: block}, {trajectory: gone.txt}]\n")
    assert message == f"sources[1].trajectory: file not found: {tmp_path / 'gone.txt'}"
    message = _problem(tmp_path, "name: x\nsources: [{kitti: '11'}]\n", data_root=tmp_path)
    assert message.startswith(f"sources[0].kitti: KITTI poses not found: {tmp_path}/kitti/poses/11.txt")
    assert _problem(tmp_path, "name: x\nsources: [{route: moon}]\n").startswith("sources[0].route: unknown route")
    duplicate = "name: x\nsources: [{route: block}, {route: block, frames: 50}]\n"
    assert _problem(tmp_path, duplicate).startswith("sources[1]: a second source named 'block'")


def test_parse_spec_from_python_names_its_origin() -> None:
    with pytest.raises(SpecError, match=r"^kitti_sim: noise: Input should be a valid list$"):
        parse_spec({"name": "x", "sources": [{"route": "block"}], "noise": "vo"}, origin="kitti_sim")


def test_cli_refuses_a_bad_spec_in_one_line(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "name: x\nsources: [{route: block}]\noverrides: {a: {matching: {min_inliers: -1}}}\n")
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith(f"neoslam: error: {spec}: overrides.a.matching.min_inliers: Input should be greater")
    assert not (tmp_path / "out").exists()


def test_every_metric_name_is_checked_before_any_work(tmp_path: Path) -> None:
    spec = _spec(tmp_path, "name: x\nsources: [{route: block}]\nmetrics: [ate_rmse_m.corrected, ate_rsme]\n")
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out"), "--workers", "0"])
    assert result.exit_code == 2
    [line] = result.output.strip().splitlines()
    assert line.startswith(f"neoslam: error: {spec}: metrics[1]: unknown metric 'ate_rsme'; known: frames, ")
    assert "ate_rmse_m.corrected" in line and not (tmp_path / "out").exists()


def test_a_measure_of_ones_own_names_its_own_metrics(tmp_path: Path) -> None:
    spec = load_spec(_spec(tmp_path, "name: x\nsources: [{route: block}]\nmetrics: [pipeline.ate_m]\n"))
    assert len(expand(spec, environ={}, measure="mine.py:measure:0").cells) == 1


def test_a_seed_is_named_by_its_place_in_the_list(tmp_path: Path) -> None:
    text = "name: x\nsources: [{route: block}]\nseeds: [1, -1]\noverrides: {a: {}, b: {matching: {min_inliers: 5}}}\n"
    assert _problem(tmp_path, text) == "seeds[1]: Input should be greater than or equal to 0 (got -1)"


def test_a_long_seed_list_is_not_spelled_out(tmp_path: Path) -> None:
    seeds = ", ".join(str(i) for i in range(10_000))
    message = _problem(
        tmp_path, f"name: x\nsources: [{{route: block}}]\nseeds: [{seeds}]\ncells: [{{source: block, seed: -5}}]\n"
    )
    assert message == "cells[0].seed: -5 is not in the spec's list [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, ... (10000 values)]"


@pytest.mark.parametrize("kind", ["folder", "pipe"])
def test_a_spec_that_is_not_a_file_is_refused_at_once(tmp_path: Path, kind: str) -> None:
    spec = tmp_path / "spec.yaml"
    if kind == "folder":
        spec.mkdir()
    else:
        os.mkfifo(spec)  # nobody writes it: opening it would wait forever
    result = CliRunner().invoke(app, ["sweep", str(spec), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    problem = "is a folder, not a spec file" if kind == "folder" else "not a regular file (a pipe or a device?)"
    assert result.output.strip().startswith(f"neoslam: error: {spec}: {problem}")
    assert not (tmp_path / "out").exists()


def test_a_source_file_that_is_a_pipe_is_refused(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "drive.txt")
    message = _problem(tmp_path, "name: x\nsources: [{trajectory: drive.txt}]\n")
    assert message == f"sources[0].trajectory: not a regular file (a pipe or a device?): {tmp_path / 'drive.txt'}"
    os.mkfifo(tmp_path / "bag")
    message = _problem(tmp_path, "name: x\nsources: [{dataset: bag}]\n")
    assert message == f"sources[0].dataset: not a regular file (a pipe or a device?): {tmp_path / 'bag'}"
