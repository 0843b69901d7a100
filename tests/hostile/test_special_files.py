"""Special files where a file is expected: a FIFO, a device or a link to one, as an input or as an output.

An input of that kind is refused in one line instead of blocking forever (a FIFO nobody writes) or reading without
end (/dev/zero); an output of that kind is never replaced by a regular file (`--json /dev/null` must not replace
the system's /dev/null). The CLI cases run as real processes with a time limit, so that a hang fails the test.
"""

from __future__ import annotations

import os
import stat
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from neoslam.errors import InputError

FIFO_PROBLEM = "is a FIFO (named pipe), not a regular file"
DEVICE_PROBLEM = "is a character device (a link to /dev/zero), not a regular file"
READER_LIMIT_S = 20


def _tum(path: Path, count: int = 20) -> Path:
    path.write_text("".join(f"{0.1 * k:.1f} {k} 0 0 0 0 0 1\n" for k in range(count)))
    return path


def _raises_promptly(call: Callable[[], Any]) -> BaseException:
    """What `call` raises, run in a thread that must finish within READER_LIMIT_S (a blocked read does not)."""
    outcome: list[BaseException | None] = []

    def target() -> None:
        try:
            call()
            outcome.append(None)
        except BaseException as error:  # noqa: BLE001 - handed back to the test
            outcome.append(error)

    worker = threading.Thread(target=target, daemon=True)
    worker.start()
    worker.join(READER_LIMIT_S)
    assert not worker.is_alive(), f"still reading after {READER_LIMIT_S} s"
    assert outcome and outcome[0] is not None, "accepted a special file"
    return outcome[0]


# --- inputs, through the CLI ---


def test_evaluate_refuses_a_fifo_as_the_estimate(tmp_path: Path, fifo, process_cli) -> None:
    result = process_cli.run("evaluate", fifo("estimate.txt"), _tum(tmp_path / "truth.txt"))
    process_cli.refused(result, "estimate.txt", FIFO_PROBLEM)


def test_evaluate_refuses_a_link_to_dev_zero_as_the_ground_truth(tmp_path: Path, zero_link, process_cli) -> None:
    result = process_cli.run("evaluate", _tum(tmp_path / "estimate.txt"), zero_link("truth.txt"))
    process_cli.refused(result, "truth.txt", DEVICE_PROBLEM)


def test_evaluate_refuses_dev_zero_itself(tmp_path: Path, process_cli) -> None:
    result = process_cli.run("evaluate", _tum(tmp_path / "estimate.txt"), "/dev/zero")
    process_cli.refused(result, "/dev/zero", "is a character device, not a regular file")


def test_run_refuses_a_fifo_as_the_config(tmp_path: Path, fifo, process_cli) -> None:
    result = process_cli.run("run", "--config", fifo("settings.yaml"), "--out", tmp_path / "out", "-q")
    process_cli.refused(result, "settings.yaml", FIFO_PROBLEM)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["run", "detect"])
def test_a_bag_that_is_a_fifo_or_a_link_to_dev_zero_is_refused(
    tmp_path: Path, fifo, zero_link, command, process_cli
) -> None:
    for bag, problem in ((fifo("pipe.bag"), FIFO_PROBLEM), (zero_link("zero.bag"), DEVICE_PROBLEM)):
        out = tmp_path / f"out-{bag.stem}" if command == "run" else tmp_path / f"{bag.stem}.jsonl"
        result = (
            process_cli.run(command, bag, "--out", out, "-q")
            if command == "run"
            else process_cli.run(command, bag, "--out", out)
        )
        process_cli.refused(result, bag.name, problem)
        assert not out.exists()


# --- inputs, reader by reader ---


def test_every_text_reader_refuses_a_fifo_without_blocking(fifo) -> None:
    from neoslam.io.trajectory_files import read_times, read_trajectory
    from neoslam.perception.detections_file import DetectionsFile
    from neoslam.text import read_yaml

    readers = {
        "trajectory.txt": lambda path: read_trajectory(path, "auto"),
        "times.txt": read_times,
        "detections.jsonl": lambda path: DetectionsFile(path, ["car"]),
        "settings.yaml": read_yaml,
    }
    for name, reader in readers.items():
        path = fifo(name)
        error = _raises_promptly(lambda reader=reader, path=path: reader(path))
        assert isinstance(error, InputError) and FIFO_PROBLEM in str(error), (name, error)


def test_an_image_a_model_and_patches_that_are_special_files_are_refused(tmp_path: Path, fifo, zero_link) -> None:
    from neoslam.datasets.kitti import read_grey_image
    from neoslam.perception.onnx_session import open_session

    image = _raises_promptly(lambda: read_grey_image(fifo("000000.png")))
    assert isinstance(image, InputError) and FIFO_PROBLEM in str(image)
    model = _raises_promptly(lambda: open_session(zero_link("model.onnx"), 1, "see the docs"))
    assert isinstance(model, InputError) and DEVICE_PROBLEM in str(model)


def test_patches_that_are_a_fifo_are_refused_with_the_dataset(tmp_path: Path) -> None:
    from neoslam.commands.simulate import record, simulate_dataset
    from neoslam.config import NeoSLAMConfig
    from neoslam.datasets.simulated import read_dataset

    folder = tmp_path / "dataset"
    simulate_dataset(folder, record(NeoSLAMConfig(), route="block"))
    patches = folder / "patches.npy"
    patches.unlink()
    os.mkfifo(patches)
    error = _raises_promptly(lambda: read_dataset(folder))
    assert isinstance(error, InputError) and FIFO_PROBLEM in str(error)


def test_an_oversized_text_input_is_refused_by_its_size(tmp_path: Path) -> None:
    from neoslam.text import read_yaml

    path = tmp_path / "huge.yaml"
    with path.open("wb") as handle:  # sparse: the size without the disk
        handle.truncate(17 * 2**20)
    with pytest.raises(InputError, match="a file of this kind holds at most"):
        read_yaml(path)


# --- outputs ---


def test_evaluate_never_replaces_a_fifo_named_as_its_json(tmp_path: Path, fifo, process_cli) -> None:
    truth = _tum(tmp_path / "truth.txt")
    target = fifo("metrics.json")
    for extra in ([], ["--overwrite"]):
        result = process_cli.run("evaluate", truth, truth, "--json", target, *extra)
        process_cli.refused(result, "metrics.json", "not a regular file")
        assert stat.S_ISFIFO(target.lstat().st_mode)


def test_evaluate_overwrites_an_existing_json_only_when_told(tmp_path: Path, process_cli) -> None:
    truth = _tum(tmp_path / "truth.txt")
    kept = tmp_path / "notes.txt"
    kept.write_text("my notes\n")
    result = process_cli.run("evaluate", truth, truth, "--json", kept)
    process_cli.refused(result, "notes.txt", "file exists (pass --overwrite to replace it)")
    assert kept.read_text() == "my notes\n"
    replaced = process_cli.run("evaluate", truth, truth, "--json", kept, "--overwrite")
    assert replaced.returncode == 0, replaced.stderr
    assert '"ate_rmse_m"' in kept.read_text()


def test_detect_never_replaces_a_fifo_named_as_its_output(tmp_path: Path, fifo, process_cli) -> None:
    target = fifo("detections.jsonl")
    result = process_cli.run("detect", tmp_path / "absent", "--out", target, "--overwrite")
    process_cli.refused(result, "detections.jsonl", "not a regular file")
    assert stat.S_ISFIFO(target.lstat().st_mode)


def test_outputs_that_are_links_to_devices_are_refused(tmp_path: Path, process_cli) -> None:
    link = tmp_path / "null.json"
    link.symlink_to("/dev/null")
    truth = _tum(tmp_path / "truth.txt")
    result = process_cli.run("evaluate", truth, truth, "--json", link, "--overwrite")
    process_cli.refused(result, "null.json", "symbolic link")
    out = tmp_path / "results"
    out.symlink_to("/dev/null")
    process_cli.refused(process_cli.run("run", "--out", out, "--overwrite", "-q"), "results", "symbolic link")
    assert Path("/dev/null").is_char_device()


def test_a_run_never_writes_its_results_over_a_fifo(tmp_path: Path, fifo, process_cli) -> None:
    target = fifo("results")
    result = process_cli.run("run", "--out", target, "--overwrite", "-q")
    process_cli.refused(result, "results", "exists and is not a folder")
    assert stat.S_ISFIFO(target.lstat().st_mode)


def test_the_stereo_step_places_at_most_max_boxes_of_a_crowded_frame() -> None:
    """3,000 boxes in one frame (a hostile detections file): the best-scored `max_boxes` are placed, the others
    dropped, so a frame's work stays bounded."""
    from neoslam.config import NeoSLAMConfig
    from neoslam.perception.detection import Detection
    from neoslam.perception.stereo import ObjectTriangulator

    config = NeoSLAMConfig()
    camera, stereo = config.simulator.camera, config.perception.stereo
    rng = np.random.default_rng(0)
    left = rng.integers(0, 256, (camera.height, camera.width), dtype=np.uint8)
    right = np.roll(left, -20, axis=1)  # every point 20 px of disparity: about 19 m away
    corners = rng.uniform([20, 20], [camera.width - 140, camera.height - 100], (3000, 2))
    boxes = np.column_stack([corners, corners + rng.uniform(30, 80, (3000, 2))])
    scores = rng.uniform(0.3, 0.9, 3000)
    best = np.argsort(-scores)[: stereo.max_boxes]
    scores[best] += 0.05  # the best are clearly the best
    detections = [Detection("car", float(s), b) for s, b in zip(scores, boxes, strict=True)]
    observations = ObjectTriangulator(camera, stereo).observe(left, right, detections)
    assert 0 < len(observations) <= stereo.max_boxes
    placed = {tuple(o.box_left) for o in observations}
    assert placed <= {tuple(boxes[i]) for i in best}
