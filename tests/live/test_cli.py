"""The ROS 2 commands refuse bad settings in one line (exit 2) before they touch DDS."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.mark.parametrize(
    ("args", "env", "parts"),
    [
        (["ros2", "--domain-id", "300"], {}, ["domain id 300", "0-232"]),
        (["ros2"], {"ROS_DOMAIN_ID": "seven"}, ["ROS_DOMAIN_ID", "'seven'"]),
        (["ros2", "--localise-only"], {}, ["--localise-only needs --map"]),
        (["ros2"], {"NEOSLAM_LIVE__LEFT_TOPIC": "/left image"}, ["live.left_topic", "ROS 2 topic name"]),
        (["ros2"], {"NEOSLAM_LIVE__MAP_FRAME": "/map"}, ["live.map_frame", "tf frame"]),
        (["ros2"], {"NEOSLAM_PERCEPTION__DETECTOR__SOURCE": "file"}, ["detects objects itself", "yolox"]),
        (["ros2-record", "--out", "BAG", "--storage", "tape", "/tf"], {}, ["unknown bag storage 'tape'"]),
    ],
)
def test_bad_settings_are_one_line(cli, tmp_path: Path, args: list[str], env: dict, parts: list[str]) -> None:
    args = [str(tmp_path / a) if a == "BAG" else a for a in args]
    result = cli.invoke(*args, env=env)
    cli.one_line_error(result, *parts)


def test_playing_needs_images_and_frames_it_holds(cli, tmp_path: Path, shared_data: Path) -> None:
    kitti = shared_data / "kitti_06_51"
    cli.one_line_error(cli.invoke("ros2-play", kitti, "--sequence", "06", "--frames", "60:70"), "--frames", "51 frames")
    cli.one_line_error(cli.invoke("ros2-play", kitti, "--sequence", "06", "--frames", "a:b"), "START:STOP")
    cli.one_line_error(cli.invoke("ros2-play", kitti, "--sequence", "06", "--rate", "0"), "--rate must be positive")
    cli.one_line_error(cli.invoke("ros2-play", tmp_path / "nowhere"), "not found")
    (tmp_path / "empty").mkdir()
    cli.one_line_error(cli.invoke("ros2-play", tmp_path / "empty"), "no stereo images here")


def test_without_the_extra_the_ros2_commands_say_how_to_install_it(cli, monkeypatch, tmp_path: Path) -> None:
    import sys

    monkeypatch.setitem(sys.modules, "cyclonedds", None)  # as if it were not installed: its import fails
    for args in (["ros2"], ["ros2-record", "/tf", "--out", tmp_path / "bag"]):
        cli.one_line_error(cli.invoke(*args), 'pip install "neoslam[ros2]"')
