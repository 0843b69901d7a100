"""The live view (`neoslam run --rerun`): a run recorded to an .rrd file and read back with Rerun's own reader has
every entity, one row per frame on the `frame` and `time` timelines, and ends with the final map; without Rerun
installed `--rerun` says how to install it; a bare `--rerun` spawns the viewer, and is refused before the run where
there is no display. (A viewer that fails: tests/hostile/test_viewer.py and test_rerun_sink.py.)"""

from __future__ import annotations

import json
import os
import signal
import socket
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

BLOCK_FRAMES = 600  # the simulated block route to its first revisit: a few loop closures
PER_FRAME = (
    "camera/detections",
    "world/robot",
    "cells/head_direction",
    "cells/grid_slice",
    "metrics/objects",
    "metrics/keyframes",
    "metrics/loop_closures",
    "metrics/experiences",
    "metrics/observations",
)
MAP_LAYERS = ("world/trajectory/odometry", "world/trajectory/corrected", "world/objects", "world/keyframes")


def _simulate(cli, root: Path, frames: int) -> Path:
    from neoslam.config import NeoSLAMConfig
    from neoslam.config.profiles import simulation_config
    from neoslam.io.trajectory_files import write_tum
    from neoslam.sim.routes import ROUTES, drive_route

    sim = simulation_config(NeoSLAMConfig(), "vo", 2, "ideal").simulator
    truth = drive_route(ROUTES["block"], sim.frame_period, sim.camera.height_above_ground)
    write_tum(root / "block.txt", truth.subset(np.arange(frames)))
    args = ("--trajectory", root / "block.txt", "--noise", "vo", "--detector", "ideal", "--seed", 2)
    cli.ok("simulate", *args, "--out", root / "data", "-q")
    return root / "data"


class Recording:
    """An .rrd file read back with rerun.chunk.RrdReader: rows per entity, timelines, and each entity's last row."""

    def __init__(self, path: Path) -> None:
        import rerun as rr

        self.rows: dict[str, int] = defaultdict(int)
        self.timelines: dict[str, set[str]] = defaultdict(set)
        self.last: dict[str, tuple[int, dict]] = {}
        for chunk in rr.chunk.RrdReader(path).stream():
            entity = chunk.entity_path.lstrip("/")
            if chunk.is_static:
                continue
            self.rows[entity] += chunk.num_rows
            self.timelines[entity].update(chunk.timeline_names)
            for row in chunk.to_record_batch().to_pylist():
                if entity not in self.last or row["frame"] >= self.last[entity][0]:
                    self.last[entity] = (row["frame"], row)


@pytest.fixture(scope="module")
def rerun_module(extra):
    rr = extra("rerun", "viewer")
    rr.set_strict_mode(True)  # a logging mistake raises instead of warning
    yield rr
    rr.set_strict_mode(False)


@pytest.fixture(scope="module")
def block_run(cli, rerun_module, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, Recording]:
    root = tmp_path_factory.mktemp("rerun")
    data = _simulate(cli, root, BLOCK_FRAMES)
    result = cli.ok("run", data, "--rerun", root / "out" / "block.rrd", "--out", root / "out", "-q")  # in the folder
    assert result.stderr == ""  # a healthy recording: no warning
    metrics = json.loads((root / "out" / "metrics.json").read_text())
    return root / "out", metrics, Recording(root / "out" / "block.rrd")


@pytest.mark.slow
def test_every_frame_is_logged_on_both_timelines(block_run) -> None:
    _, metrics, recording = block_run
    assert metrics["frames"] == BLOCK_FRAMES and metrics["loops"]["accepted"] > 0
    for entity in PER_FRAME:
        assert recording.rows[entity] == BLOCK_FRAMES, entity
        assert {"frame", "time"} <= recording.timelines[entity], entity
    assert recording.rows["metrics/frame_ms"] == BLOCK_FRAMES - 1  # the time between two frames
    assert "camera/image" not in recording.rows  # a simulated dataset has no images


@pytest.mark.slow
def test_the_map_layers_end_with_the_final_map(block_run) -> None:
    out, metrics, recording = block_run
    for entity in (*MAP_LAYERS, "world/loop_closures"):
        assert 0 < recording.rows[entity] < BLOCK_FRAMES, entity  # logged when the map changes, not every frame
        assert recording.last[entity][0] == BLOCK_FRAMES - 1, entity
    last = {entity: row for entity, (_, row) in recording.last.items()}
    assert len(last["world/objects"]["Points3D:positions"]) == metrics["objects"]
    assert len(last["world/keyframes"]["Points3D:positions"]) == metrics["keyframes"]
    assert len(last["world/loop_closures"]["LineStrips3D:strips"]) == metrics["loops"]["accepted"]
    corrected = np.array(last["world/trajectory/corrected"]["LineStrips3D:strips"][0])
    trajectory = np.loadtxt(out / "trajectory_tum.txt")[:, 1:4]
    np.testing.assert_allclose(corrected, trajectory, atol=1e-5)  # float32 in the recording
    assert last["metrics/loop_closures"]["Scalars:scalars"] == [metrics["loops"]["accepted"]]


@pytest.mark.slow
def test_the_results_folder_holds_the_pose_graph(block_run) -> None:
    out, metrics, _ = block_run
    lines = (out / "experience_map.g2o").read_text().splitlines()
    assert sum(line.startswith("VERTEX_SE3:QUAT ") for line in lines) == metrics["experience_map"]["experiences"]
    assert sum(line.startswith("EDGE_SE3:QUAT ") for line in lines) == metrics["experience_map"]["links"]


@pytest.mark.slow
def test_an_image_sequence_logs_its_left_images(cli, rerun_module, shared_data: Path, tmp_path: Path) -> None:
    model = shared_data / "models" / "yolox_nano_coco" / "yolox_nano.onnx"
    env = {"NEOSLAM_PERCEPTION__DETECTOR__MODEL": str(model)}
    root = shared_data / "kitti_mini"
    cli.ok("run", root, "--sequence", "06", "--out", tmp_path / "out", "--rerun", tmp_path / "mini.rrd", "-q", env=env)
    recording = Recording(tmp_path / "mini.rrd")
    assert recording.rows["camera/image"] == recording.rows["camera/detections"] == 12
    image = recording.last["camera/image"][1]
    assert image["EncodedImage:media_type"] == ["image/jpeg"]
    labels = recording.last["camera/detections"][1]["Boxes2D:labels"] or []  # "car 0.87": class and score
    assert all(label.split()[0] in ("car", "truck", "bicycle", "person") for label in labels)


@pytest.mark.slow
def test_a_bare_rerun_starts_the_viewer_or_uses_the_one_listening(
    cli, rerun_module, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import rerun_cli

    from neoslam.viz import rerun_target

    real = Path(rerun_cli.__file__).with_name("rerun")
    if not real.exists():
        pytest.skip(f"the Rerun viewer's binary is not at {real}")
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    monkeypatch.setattr(rerun_target, "VIEWER_PORT", port)
    # A stand-in for the viewer, found on PATH: the real Rerun server without a window, on the port it is given.
    viewer, started, pid = tmp_path / "bin" / "rerun", tmp_path / "started.txt", tmp_path / "viewer.pid"
    viewer.parent.mkdir()
    viewer.write_text(f'#!/bin/sh\necho "$@" >> "{started}"\necho $$ > "{pid}"\nexec "{real}" --serve-grpc "$1"\n')
    viewer.chmod(0o755)
    monkeypatch.setenv("PATH", f"{viewer.parent}{os.pathsep}{os.environ.get('PATH', '')}")
    monkeypatch.setenv("DISPLAY", ":0")
    data = _simulate(cli, tmp_path, 30)
    try:
        first = cli.ok("run", data, "--out", tmp_path / "out", "--rerun", "-q")
        second = cli.ok("run", data, "--rerun", "--out", tmp_path / "out2", "-q")  # DATA before it is not the file
    finally:
        if pid.exists():
            os.kill(int(pid.read_text()), signal.SIGKILL)
    assert first.stderr == second.stderr == ""
    assert started.read_text().splitlines() == [f"--port={port} --memory-limit=75% --expect-data-soon"]  # once


def test_without_the_viewer_executable_a_bare_rerun_says_how_to_get_it(
    cli, rerun_module, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setenv("DISPLAY", ":0")
    data = _simulate(cli, tmp_path, 30)
    result = cli.invoke("run", data, "--rerun", "--out", tmp_path / "out", "-q")
    line = cli.one_line_error(result, "Rerun viewer (`rerun`) is not on PATH", "--rerun FILE.rrd")
    assert line and not (tmp_path / "out").exists()


@pytest.mark.parametrize("variable", ["DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"])
def test_a_display_is_one_of_the_desktops_variables_or_a_desktop_platform(variable: str) -> None:
    from neoslam.viz.rerun_view import has_display

    assert has_display({variable: ":0"}, "linux") and has_display({variable: "wayland-0"}, "freebsd14")
    assert not has_display({}, "linux") and not has_display({variable: ""}, "linux")
    assert has_display({}, "darwin") and has_display({}, "win32")


def test_without_a_display_a_bare_rerun_is_refused_before_the_run(
    cli, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    for variable in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"):
        monkeypatch.delenv(variable, raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    result = cli.invoke("run", tmp_path / "nowhere", "--rerun", "--out", tmp_path / "out", "-q")  # before the data
    line = cli.one_line_error(result, "no display", "DISPLAY", "--rerun FILE.rrd")
    assert line and not (tmp_path / "out").exists()


def test_a_recording_must_end_in_rrd(cli, rerun_module, tmp_path: Path) -> None:
    result = cli.invoke("run", tmp_path / "nowhere", "--rerun=notes.txt", "--out", tmp_path / "out", "-q")
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == ["neoslam: error: --rerun takes no value (spawn the viewer) or a "
                                                  "file ending .rrd, not 'notes.txt'"]  # fmt: skip


def test_without_the_viewer_extra_rerun_says_how_to_install_it(cli, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun now fails as if it were not installed
    data = _simulate(cli, tmp_path, 30)
    result = cli.invoke("run", data, "--rerun", tmp_path / "run.rrd", "--out", tmp_path / "out", "-q")
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and 'pip install "neoslam[viewer]"' in lines[0]
    assert not (tmp_path / "out").exists() and not (tmp_path / "run.rrd").exists()


@pytest.mark.slow
def test_a_goals_guidance_is_shown_with_the_route(cli, rerun_module, tmp_path: Path) -> None:
    data = _simulate(cli, tmp_path, BLOCK_FRAMES)
    cli.ok("run", data, "--goal", "start", "--rerun", tmp_path / "guided.rrd", "--out", tmp_path / "out", "-q")
    recording = Recording(tmp_path / "guided.rrd")
    for entity in ("world/route", "world/waypoint", "guidance/state"):
        assert recording.rows[entity] >= 1, entity
    assert recording.rows["world/waypoint"] == BLOCK_FRAMES  # the first session is in the map's frame throughout
    assert recording.rows["guidance/remaining_m"] == BLOCK_FRAMES
