"""Expanding a spec: the grid, a list of cells, stable ids, shared simulations, and configs resolved as the CLI
and the benchmarks resolve them."""

from __future__ import annotations

from pathlib import Path

import pytest

from neoslam.commands.run import with_backend
from neoslam.config import NeoSLAMConfig, load_config
from neoslam.config.profiles import simulation_config
from neoslam.sweep import expand, parse_spec
from neoslam.sweep.cells import ID_LENGTH, RUN_ONLY_SECTIONS, axes_that_vary, content_hash
from neoslam.sweep.driver import _tasks


def _spec(tmp_path: Path, **values):
    return parse_spec({"name": "t", "sources": [{"route": "block"}]} | values, "t.yaml", tmp_path)


def _trajectory(tmp_path: Path, name: str = "drive.txt", shift: float = 0.0) -> Path:
    lines = [f"{0.1 * i:.1f} {i + shift:.1f} 0 0 0 0 0 1" for i in range(5)]
    (tmp_path / name).write_text("\n".join(lines) + "\n")
    return tmp_path / name


def test_grid_is_sources_x_noise_x_detectors_x_seeds_x_overrides(tmp_path: Path) -> None:
    _trajectory(tmp_path)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "dataset.yaml").write_text("format: neoslam-sim\n")
    spec = _spec(
        tmp_path,
        sources=[{"route": "block"}, {"trajectory": "drive.txt"}, {"dataset": "data"}],
        noise=["vo", "heavy"],
        detectors=["real", "ideal"],
        seeds=[1, 2],
        overrides={"a": {}, "b": {"matching": {"min_inliers": 5}}},
    )
    cells = expand(spec, environ={}).cells
    # 2 simulated sources x 2 x 2 x 2 x 2, and the dataset once per override (it is run as it is)
    assert len(cells) == 2 * 16 + 2
    first = cells[0]
    assert (first.source, first.noise, first.detector, first.seed, first.override) == ("block", "vo", "real", 1, "a")
    assert [c.override for c in cells[:2]] == ["a", "b"]  # overrides vary fastest, then seeds, ...
    assert [c.seed for c in cells[:4]] == [1, 1, 2, 2]
    assert [(c.source, c.noise, c.seed) for c in cells[-2:]] == [("data", None, None), ("data", None, None)]
    assert [c.index for c in cells] == list(range(len(cells)))
    assert len({c.id for c in cells}) == len(cells)
    assert axes_that_vary(cells) == ["source", "noise", "detector", "override"]  # never the seed


def test_a_list_of_cells_picks_and_defaults(tmp_path: Path) -> None:
    spec = _spec(
        tmp_path,
        noise=["vo", "heavy"],
        seeds=[1, 2, 3],
        overrides={"a": {}, "b": {"matching": {"min_inliers": 5}}},
        cells=[{"source": "block", "seed": 3, "override": "b"}, {"source": "block", "noise": "heavy"}],
    )
    cells = expand(spec, environ={}).cells
    assert [(c.noise, c.detector, c.seed, c.override) for c in cells] == [
        ("vo", "real", 3, "b"),
        ("heavy", "real", 1, "a"),
    ]


def test_ids_follow_content_not_names(tmp_path: Path) -> None:
    _trajectory(tmp_path)
    base = {"sources": [{"trajectory": "drive.txt"}], "overrides": {"a": {"matching": {"min_inliers": 5}}}}
    ids = [c.id for c in expand(_spec(tmp_path, **base), environ={}).cells]
    assert ids == [c.id for c in expand(_spec(tmp_path, **base), environ={}).cells]  # stable
    renamed = {"sources": [{"trajectory": "drive.txt", "name": "mine"}], "overrides": {"z": base["overrides"]["a"]}}
    assert [c.id for c in expand(_spec(tmp_path, **renamed), environ={}).cells] == ids
    _trajectory(tmp_path, shift=0.5)  # the same file, other poses
    assert [c.id for c in expand(_spec(tmp_path, **base), environ={}).cells] != ids
    _trajectory(tmp_path)
    other_seed = base | {"seeds": [2]}
    assert [c.id for c in expand(_spec(tmp_path, **other_seed), environ={}).cells] != ids
    environment = {"NEOSLAM_MATCHING__MIN_SUPPORT": "3"}  # the config's variables are part of the config
    assert [c.id for c in expand(_spec(tmp_path, **base), environ=environment).cells] != ids
    assert [c.id for c in expand(_spec(tmp_path, **base), environ={}, measure="mine").cells] != ids


def test_run_only_overrides_share_one_simulation(tmp_path: Path) -> None:
    spec = _spec(
        tmp_path,
        seeds=[1, 2],
        overrides={
            "graph": {},
            "relaxation": {"experience_map": {"backend": "relaxation"}},
            "sparse": {"simulator": {"world": {"occupancy": 0.2}}},
        },
    )
    plan = expand(spec, environ={})
    keys = [c.simulation for c in plan.cells]
    assert keys[0] == keys[1] != keys[2]  # the back end is the run's; the street is the simulation's
    assert keys[0] != keys[3]  # another seed
    tasks = _tasks(plan, plan.cells, workers=2, keep=False, measure=None, remote=False)
    assert [[c.index for c in t.cells] for t in tasks] == [[0, 1], [2], [3, 4], [5]]
    split = _tasks(plan, plan.cells[:2], workers=2, keep=False, measure=None, remote=False)
    assert [[c.index for c in t.cells] for t in split] == [[0], [1]]  # fewer groups than workers: split


def test_restating_a_default_shares_the_cell(tmp_path: Path) -> None:
    spec = _spec(tmp_path, overrides={"default": {}, "graph": {"experience_map": {"backend": "pose-graph"}}})
    cells = expand(spec, environ={}).cells
    assert cells[0].id == cells[1].id


@pytest.mark.parametrize(("noise", "detector", "backend"), [("vo", "real", None), ("heavy", "ideal", "relaxation")])
def test_configs_resolve_as_the_cli_resolves_them(tmp_path: Path, noise: str, detector: str, backend) -> None:
    override = {"experience_map": {"backend": backend}} if backend else {}
    spec = _spec(tmp_path, noise=[noise], detectors=[detector], seeds=[7], overrides={"x": override})
    config = expand(spec, environ={}).cells[0].config
    expected = with_backend(simulation_config(load_config(environ={}), noise, 7, detector), backend)
    assert config == expected


def test_a_config_file_lies_under_the_overrides(tmp_path: Path) -> None:
    (tmp_path / "base.yaml").write_text("matching: {min_inliers: 6, min_support: 3}\n")
    spec = _spec(tmp_path, config="base.yaml", overrides={"x": {"matching": {"min_inliers": 5}}})
    plan = expand(spec, environ={})
    assert plan.cells[0].config.matching.min_inliers == 5
    assert plan.cells[0].config.matching.min_support == 3
    assert tmp_path / "base.yaml" in plan.inputs
    assert NeoSLAMConfig().matching.min_support != 3


def test_a_cell_id_is_the_hash_of_its_whole_resolved_config(tmp_path: Path) -> None:
    overrides = {"a": {}, "fixed": {"simulator": {"seed": 5}}, "b": {"experience_map": {"backend": "relaxation"}}}
    spec = _spec(tmp_path, noise=["vo", "heavy"], seeds=[0, 7, 42, 123456789012], overrides=overrides)
    plan = expand(spec, environ={})
    for cell in plan.cells:
        content = plan.sources[cell.source].content
        resolved = cell.config.model_dump(mode="json")
        assert cell.id == content_hash(content, resolved, plan.code_version, plan.measure)[:ID_LENGTH]
        simulated = {k: v for k, v in resolved.items() if k not in RUN_ONLY_SECTIONS}
        assert cell.simulation == content_hash(content, simulated)[:ID_LENGTH]
        assert resolved["simulator"]["seed"] == (5 if cell.override == "fixed" else cell.seed)
    assert len({id(c.setting) for c in plan.cells}) == 2 * 3  # a config checked per noise and override, not per seed
    fixed = {c.id for c in plan.cells if c.override == "fixed" and c.noise == "vo"}
    assert len(fixed) == 1  # the override's seed wins: one run
