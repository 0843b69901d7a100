"""Messages that must say what is wrong, where: the value a setting was given, the line of a table, a position that
is not finite, a file name that is not UTF-8."""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from neoslam.config import load_config
from neoslam.errors import ConfigError, InputError
from neoslam.io.trajectory_files import read_trajectory


@pytest.mark.parametrize("value", ["off", "on", "yes", "no"])
def test_yaml_1_1_booleans_stay_text_in_variables_and_files(tmp_path: Path, value: str) -> None:
    """`synchronous: off` is the text "off" (refused as a value the setting does not have), never False."""
    with pytest.raises(ConfigError, match=f"map_store.synchronous: .*got '{value}'"):
        load_config(environ={"NEOSLAM_MAP_STORE__SYNCHRONOUS": value})
    config = tmp_path / "settings.yaml"
    config.write_text(f"map_store:\n  synchronous: {value}\n")
    with pytest.raises(ConfigError, match=f"got '{value}'"):
        load_config(config, environ={})


def test_true_and_false_are_still_booleans(tmp_path: Path) -> None:
    config = tmp_path / "settings.yaml"
    config.write_text("moving_objects:\n  enabled: false\n")
    assert load_config(config, environ={}).moving_objects.enabled is False


def _odometry_message(position: list[float], orientation: list[float]) -> SimpleNamespace:
    point = SimpleNamespace(x=position[0], y=position[1], z=position[2])
    turn = SimpleNamespace(x=orientation[0], y=orientation[1], z=orientation[2], w=orientation[3])
    return SimpleNamespace(pose=SimpleNamespace(pose=SimpleNamespace(position=point, orientation=turn)))


@pytest.mark.parametrize(
    ("position", "orientation", "problem"),
    [
        ([np.nan, 0, 0], [0, 0, 0, 1], "odometry position is not finite (nan, 0, 0)"),
        ([0, 0, 0], [0, 0, np.inf, 1], "odometry orientation is not finite"),
        ([0, 0, 0], [0, 0, 0, 2], "not a unit quaternion (norm 2.0000)"),
    ],
)
def test_an_odometry_message_is_refused_for_what_is_wrong_with_it(position, orientation, problem) -> None:
    from neoslam.datasets.bag_messages import MessageError, odometry_pose

    with pytest.raises(MessageError) as caught:
        odometry_pose(_odometry_message(position, orientation))
    assert problem in str(caught.value)


def test_simulated_detections_of_classes_the_detector_leaves_out_are_left_out(tmp_path: Path) -> None:
    from neoslam.commands.simulate import record, simulate_dataset
    from neoslam.config import NeoSLAMConfig
    from neoslam.datasets.simulated import read_dataset

    folder = tmp_path / "dataset"
    simulate_dataset(folder, record(NeoSLAMConfig(), route="block"))
    table = (folder / "detections.csv").read_text().splitlines()
    renamed = [table[0]] + [line.replace(",car,", ",zebra,", 1) for line in table[1:]]
    (folder / "detections.csv").write_text("\n".join(renamed) + "\n")
    every = {o.label for frame in read_dataset(folder).frames() for o in frame.observations}
    kept = {o.label for frame in read_dataset(folder, classes=["car", "truck"]).frames() for o in frame.observations}
    assert "zebra" in every and "zebra" not in kept and kept <= {"car", "truck"}


@pytest.mark.slow
def test_a_file_name_that_is_not_utf8_is_printed_with_its_bytes_escaped(tmp_path: Path, process_cli) -> None:
    out = Path(os.fsdecode(os.fsencode(tmp_path) + b"/seq\xff"))
    result = process_cli.run("simulate", "--route", "block", "--out", out, "-q")
    assert result.returncode == 0, result.stderr
    assert "seq\\xff" in result.stdout and out.is_dir()
    run = process_cli.run("run", out, "--out", tmp_path / "results", "--map", tmp_path / "map.db", "-q")
    assert run.returncode == 0, run.stderr
    assert "in the map's frame" in run.stdout


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("huge_quaternion.txt", "0 0 0 0 0 0 0 1\n0.1 1 0 0 0 0 1e300 1\n"),
        ("huge_rotation.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n1e300 0 0 1 0 1 0 0 0 0 1 0\n"),
    ],
)
def test_a_huge_orientation_value_is_refused_without_a_numeric_warning(tmp_path: Path, name: str, text: str) -> None:
    # A warning printed before the error line would make the refusal three lines instead of one.
    path = tmp_path / name
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(InputError, match=":2: (non-unit quaternion|rotation is not orthonormal)"):
            read_trajectory(path, "tum" if "quaternion" in name else "kitti")
