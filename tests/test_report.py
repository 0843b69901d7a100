"""`neoslam report`: one self-contained HTML page (figures embedded, no script, no external address) of one run or
several side by side: the metrics as metrics.json has them, the figures the runs wrote, the time by stage and the
configuration that differed; bad folders get one line; the same folders give the same bytes; a headless Chromium
renders it to a page that is not blank."""

from __future__ import annotations

import html
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from neoslam.commands.run import write_results
from neoslam.commands.run_metrics import run_metrics
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.report.results import FIGURES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def folders(block_seed5: Path, _block_seed5_run, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The block drive's results folder, written as `neoslam run` writes it (the default back end, pose-graph), and
    a copy whose configuration says the paper's relaxation."""
    root = tmp_path_factory.mktemp("report")
    dataset, result, config = read_dataset(block_seed5), _block_seed5_run.copy(), NeoSLAMConfig()
    first = root / "pose_graph"
    first.mkdir()
    write_results(first, dataset, result, config, run_metrics(dataset, result, config, 1.0), None)
    second = root / "other"
    shutil.copytree(first, second)
    settings = yaml.safe_load((second / "config.yaml").read_text())
    settings["experience_map"]["backend"] = "relaxation"
    (second / "config.yaml").write_text(yaml.safe_dump(settings))
    return first, second


def test_one_run_is_one_self_contained_page(cli, folders, tmp_path: Path) -> None:
    first, _ = folders
    out = tmp_path / "report.html"
    cli.ok("report", first, "--out", out)
    page = out.read_text()
    assert page.startswith("<!DOCTYPE html>") and "<script" not in page and "<link" not in page
    assert not re.search(r"(src|href)=\"(?!data:)", page) and "http://" not in page and "https://" not in page
    assert str(first.parent) not in page  # the folder's name, never the machine's path
    plots = {p.name for p in (first / "plots").iterdir()} & set(FIGURES)
    assert len(plots) >= 4 and page.count("data:image/png;base64,") == len(plots)
    assert all(html.escape(FIGURES[name]) in page for name in plots)
    metrics = yaml.safe_load((first / "metrics.json").read_text())
    assert f"{metrics['ate_rmse_m']['corrected']:.4g}" in page and "keyframe frames" in page
    assert "No setting differs." in page  # the defaults, as run


def test_several_runs_side_by_side_show_the_setting_that_differed(cli, folders, tmp_path: Path) -> None:
    out = tmp_path / "both.html"
    cli.ok("report", *folders, "--out", out)
    page = out.read_text()
    assert "<th>pose_graph</th><th>other</th>" in page
    row = re.search(r"<tr><th>experience_map\.backend</th>(.*?)</tr>", page)
    assert row is not None and row.group(1) == "<td>pose-graph</td><td>relaxation</td>"
    assert len(re.findall(r"<tr><th>[^<]+</th><td", page.split("Configuration that differed")[1])) == 1
    again = tmp_path / "again.html"
    cli.ok("report", *folders, "--out", again)
    assert again.read_bytes() == out.read_bytes()


def test_folders_of_one_name_are_told_apart(cli, folders, tmp_path: Path) -> None:
    first, _ = folders
    copies = [tmp_path / side / "results" for side in ("a", "b")]
    for copy in copies:
        shutil.copytree(first, copy)
    out = tmp_path / "same.html"
    cli.ok("report", *copies, "--out", out)
    assert "<th>a/results</th><th>b/results</th>" in out.read_text()


def test_bad_folders_and_outputs_are_one_line_and_write_nothing(cli, folders, tmp_path: Path) -> None:
    first, _ = folders
    out = tmp_path / "r.html"
    cli.one_line_error(cli.invoke("report", tmp_path / "absent", "--out", out), "absent", "not found")
    (tmp_path / "empty").mkdir()
    cli.one_line_error(cli.invoke("report", tmp_path / "empty", "--out", out), "no metrics.json")
    broken = tmp_path / "in" / "broken"
    shutil.copytree(first, broken)
    (broken / "metrics.json").write_text('{"frames": 3,\n oops}')
    cli.one_line_error(cli.invoke("report", broken, "--out", out), "metrics.json:2", "not valid JSON")
    (broken / "metrics.json").write_text((first / "metrics.json").read_text())
    (broken / "config.yaml").write_text("mapping:\n  a: [1,\n")
    cli.one_line_error(cli.invoke("report", broken, "--out", out), "config.yaml", "not valid YAML")
    (broken / "config.yaml").write_text((first / "config.yaml").read_text())
    (broken / "plots" / "map_2d.png").write_text("not an image")
    cli.one_line_error(cli.invoke("report", broken, "--out", out), "map_2d.png", "not a PNG")
    assert not out.exists() and not list(tmp_path.glob(".*partial*"))
    cli.one_line_error(cli.invoke("report", first, "--out", first / "metrics.json"), "metrics.json")
    out.write_text("mine")
    cli.one_line_error(cli.invoke("report", first, "--out", out), str(out))
    assert out.read_text() == "mine"
    cli.ok("report", first, "--out", out, "--overwrite")
    assert out.read_text().startswith("<!DOCTYPE html>")


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium here (Debian: apt-get install chromium)")
def test_chromium_renders_the_report_to_a_page_that_is_not_blank(cli, folders, tmp_path: Path) -> None:
    out, shot = tmp_path / "report.html", tmp_path / "shot.png"
    cli.ok("report", *folders, "--out", out)
    command = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
               "--window-size=1200,1600", f"--screenshot={shot}", out.resolve().as_uri()]  # fmt: skip
    subprocess.run(command, check=True, capture_output=True, timeout=120)
    image = cv2.imread(str(shot))
    assert image is not None and image.shape[:2] == (1600, 1200)
    ink = (image < 200).any(axis=2)
    assert 0.02 < ink.mean() < 0.9  # text, tables and plots on a white page
    assert len(np.unique(image.reshape(-1, 3)[::97], axis=0)) > 50  # the plots' colours, not text alone
