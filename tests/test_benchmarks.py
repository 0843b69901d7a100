"""The benchmarks' harness: the shared arguments, the stamp of a result, the data check, the renderer of the
documentation's tables, and that every benchmark imports and has a quick mode (none is run here: `make bench`)."""

from __future__ import annotations

import importlib
import json
import math
from pathlib import Path

import numpy as np
import pytest
from benchmarks import _figures, harness, render


def _start(tmp_path: Path, *argv: str, arguments=None) -> harness.Run:
    return harness.start("benchmarks.example", "An example.\n\nMore.", "a tiny run", arguments, list(argv))


def test_the_shared_arguments_and_where_the_result_goes(tmp_path: Path) -> None:
    run = _start(tmp_path)
    assert not run.quick and run.args.workers == harness.default_workers() and not run.args.no_save
    assert run.out == harness.RESULTS / "example.json"
    assert _start(tmp_path, "--quick").out == harness.RESULTS / "example.quick.json"
    run = _start(tmp_path, "--quick", "--workers", "3", "--out", str(tmp_path / "x.json"))
    assert run.quick and run.args.workers == 3 and run.out == tmp_path / "x.json"
    run = _start(tmp_path, "--seeds", "4", "5", arguments=lambda p: p.add_argument("--seeds", nargs="+", type=int))
    assert run.args.seeds == [4, 5]
    with pytest.raises(SystemExit):
        _start(tmp_path, "--no-such-option")


def test_a_result_is_stamped_with_the_run_that_made_it(tmp_path: Path, capsys) -> None:
    out = tmp_path / "example.json"
    run = _start(tmp_path, "--quick", "--out", str(out))
    run.table("drives", [{"sequence": "05", "ate_m": 1.23456, "ok": True}], ["sequence", "ate_m"], title="ATE:")
    run.finish({"median": np.float64(1.5), "missing": float("nan"), "counts": np.arange(3)})
    printed = capsys.readouterr().out
    assert "ATE:" in printed and "| 05 | 1.235 |" in printed
    result = json.loads(out.read_text())
    assert result["benchmark"] == "example" and result["quick"] is True
    assert result["command"] == "python -m benchmarks.example --quick"  # no path of the machine that ran it
    assert set(result["git"]) == {"commit", "dirty"}
    assert {"cpu", "cores", "ram_gb", "python", "platform", "libraries"} <= set(result["machine"])
    assert "numpy" in result["machine"]["libraries"]
    assert set(result["load_average"]) == {"start", "end"} and len(result["load_average"]["end"]) == 3
    assert result["started"].endswith("+00:00") and result["wall_s"] >= 0
    assert result["tables"]["drives"] == {
        "title": "ATE:",
        "columns": ["sequence", "ate_m"],
        "rows": [{"sequence": "05", "ate_m": 1.23456}],
    }
    assert result["figures"] == {"median": 1.5, "missing": None, "counts": [0, 1, 2]}


def test_no_save_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "example.json"
    _start(tmp_path, "--no-save", "--out", str(out)).finish({"x": 1})
    assert not out.exists()


def test_a_missing_dataset_is_one_line_and_exit_code_2(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.setenv("NEOSLAM_DATA", str(tmp_path))
    assert harness.require_data() == tmp_path.resolve()
    with pytest.raises(SystemExit) as stopped:
        harness.start("benchmarks.example", "An example.", "tiny", argv=[], data=(("kitti", "poses"),))
    assert stopped.value.code == 2
    message = capsys.readouterr().err
    assert message.count("\n") == 1 and str(tmp_path / "kitti" / "poses") in message and "NEOSLAM_DATA" in message


def test_jsonable_gives_plain_json() -> None:
    value = harness.jsonable({1: (np.int64(2), math.inf), "p": Path("/a")})
    assert value == {"1": [2, None], "p": "/a"}


def _stored(folder: Path) -> None:
    result = {
        "benchmark": "example",
        "command": "python -m benchmarks.example",
        "started": "2026-01-02T03:04:05+00:00",
        "wall_s": 90.0,
        "git": {"commit": "0123456789abcdef", "dirty": False},
        "machine": {"cpu": "Some CPU", "cores": 2, "ram_gb": 8.0, "python": "3.11.7"},
        "load_average": {"start": [0.5, 0.4, 0.3], "end": [1.5, 1.0, 0.5]},
        "tables": {
            "drives": {
                "title": "## Drives",
                "columns": ["sequence", "ate_m"],
                "rows": [{"sequence": "05", "ate_m": 1.5}],
            }
        },
        "figures": {},
    }
    (folder / "example.json").write_text(json.dumps(result))


def test_the_renderer_fills_the_marked_tables_from_the_stored_result(tmp_path: Path) -> None:
    pages, results = tmp_path / "pages", tmp_path / "results"
    pages.mkdir()
    results.mkdir()
    _stored(results)
    page = pages / "example.md"
    page.write_text(
        "# Example\n\nProse.\n\n<!-- results: example drives -->\nold\n<!-- end results -->\n\nMore prose.\n"
    )
    arguments = ["--pages", str(pages), "--results", str(results)]
    assert render.main([*arguments, "--check"]) == 1
    assert "old" in page.read_text()  # --check writes nothing
    assert render.main(arguments) == 0
    text = page.read_text()
    assert text.startswith("# Example\n\nProse.\n\n<!-- results: example drives -->\n*Measured by ")
    assert "`python -m benchmarks.example`" in text and "2026-01-02 03:04 UTC" in text and "0123456789" in text
    assert "Some CPU, 2 cores" in text and "load average 0.5 at the start, 1.5 at the end" in text
    assert "Drives\n\n| sequence | ate_m |\n|---|---|\n| 05 | 1.500 |\n<!-- end results -->\n\nMore prose.\n" in text
    assert render.main([*arguments, "--check"]) == 0


def test_the_renderer_names_an_unknown_table_and_a_missing_result(tmp_path: Path) -> None:
    _stored(tmp_path)
    with pytest.raises(KeyError, match="no table 'nope'"):
        render.render_page("<!-- results: example nope -->\n<!-- end results -->\n", tmp_path)
    text = render.render_page("<!-- results: absent drives -->\n<!-- end results -->\n", tmp_path)
    assert "No stored result: run `python -m benchmarks.absent`" in text


@pytest.mark.slow  # the first import brings in torch, OpenCV and the pipeline: seconds
@pytest.mark.parametrize("name", harness.benchmark_names())
def test_every_benchmark_imports_and_has_a_quick_mode(name: str) -> None:
    module = importlib.import_module(f"benchmarks.{name}")
    assert callable(module.main) and isinstance(module.QUICK, str) and module.QUICK
    description = module.__doc__.split("\n\n")[0]
    parser = harness.make_parser(description, module.QUICK, getattr(module, "arguments", None))
    assert parser.parse_args(["--quick"]).quick


def test_the_benchmarks_are_the_documented_ones() -> None:
    readme = (harness.REPO_ROOT / "benchmarks" / "README.md").read_text()
    for name in harness.benchmark_names():
        assert f"`{name}`" in readme, f"benchmarks/README.md does not describe {name}"


def test_the_renderer_draws_the_marked_figures_from_the_stored_result(tmp_path: Path) -> None:
    """A figure marker becomes the figure's image, drawn from the stored table into figures/ as SVG; the same result
    draws the same bytes, so --check then finds nothing stale; a figure the renderer does not know is one line."""
    pages, results = tmp_path / "pages", tmp_path / "results"
    pages.mkdir()
    results.mkdir()
    rows = [{"experiences": n, "plan_ms_median": n / 5000, "plan_ms_p95": n / 4000, "graph_ms": n / 300}
            for n in (1000, 5000, 20000)]  # fmt: skip
    stored = {"benchmark": "navigation", "command": "python -m benchmarks.navigation", "started": "2026-01-02T03:04",
              "tables": {"planning": {"title": "", "columns": list(rows[0]), "rows": rows}}}  # fmt: skip
    (results / "navigation.json").write_text(json.dumps(stored))
    page = pages / "navigation.md"
    page.write_text("Prose.\n\n<!-- figure: navigation planning -->\nold\n<!-- end figure -->\n")
    arguments = ["--pages", str(pages), "--results", str(results)]
    assert render.main([*arguments, "--check"]) == 1 and not (pages / "figures").exists()
    assert render.main(arguments) == 0
    assert "![Route planning time against map size](figures/navigation-planning.svg)" in page.read_text()
    svg = (pages / "figures" / "navigation-planning.svg").read_text()
    assert svg.startswith("<?xml") and "Route planning against map size" in svg and "<dc:date>" not in svg
    assert render.main([*arguments, "--check"]) == 0  # drawn again, the same bytes
    page.write_text("<!-- figure: navigation nothing -->\n<!-- end figure -->\n")
    assert render.main(arguments) == 2


def test_the_trajectory_figure_draws_each_drive_with_its_paths_closures_and_classes() -> None:
    """A panel a drive (titled with its ATE and closures) and a legend naming the paths, true and false closures
    and each class of object."""
    drive = {
        "drive": "05",
        "ate_m": 1.5,
        "closures": 2,
        "paths": {name: [[0.0, 0.0], [10.0, 1.0], [20.0, 0.0]] for name in ("truth", "odometry", "corrected")},
        "closure_points": [[10.0, 1.0], [20.0, 0.0]],
        "closure_true": [True, False],
        "object_points": [[5.0, 3.0], [15.0, -3.0]],
        "object_labels": ["car", "person"],
    }
    real = drive | {"drive": "real", "ate_m": None, "closures": 0, "closure_points": [], "closure_true": []}
    figure = _figures.drive_trajectories({"figures": {"drives": [drive, real]}})
    titles = [axes.get_title() for axes in figure.axes]
    assert titles[:2] == ["05: ATE 1.50 m, 2 closures", "real: ATE -, 0 closures"]
    legend = figure.axes[2].get_legend()
    assert [t.get_text() for t in legend.get_texts()] == [
        "corrected map", "ground truth", "odometry", "closure (false)", "closure (true)", "object: car",
        "object: person",
    ]  # fmt: skip
    svg = _figures.svg_text(figure)
    assert "closure (false)" in svg and "object: person" in svg
