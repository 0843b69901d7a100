"""The sweep spec: its YAML form, and one line naming the spec file and the field for every mistake."""

from __future__ import annotations

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
        ("name: x\nsources: [{route: block}]\nseeds: [1, 1]\n", "seeds: each value once"),
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
