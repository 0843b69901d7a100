"""The live node (`neoslam ros2`): the ROS 2 topics it reads and writes, its frames, and how it keeps up."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, field_validator

from neoslam.config.base import Section

__all__ = ["LiveConfig"]

TOPIC_CHARACTERS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_/~{}")


def _check_topic(name: str) -> str:
    """ROS 2 topic names: letters, digits, underscores and slashes; a leading slash for absolute names."""
    if not name or not set(name) <= TOPIC_CHARACTERS or "//" in name or name.endswith("/"):
        raise ValueError(f"{name!r} is not a ROS 2 topic name (letters, digits, _ and /, e.g. /left/image_raw)")
    return name


class LiveConfig(Section):
    """A live stereo camera over ROS 2 (DDS): the node subscribes to the two cameras' images and CameraInfo (and
    optionally an odometry topic), maps as `neoslam run` does, and publishes the corrected pose, tf, the path, the
    mapped objects, events (loop closures, relocalisation) and its status."""

    left_topic: str = Field(
        "/left/image_raw",
        description="left camera's sensor_msgs/Image; a name ending /compressed is read as sensor_msgs/CompressedImage",
    )
    right_topic: str = Field("/right/image_raw", description="right camera's image topic, as left_topic")
    left_info_topic: str | None = Field(
        None, description="left sensor_msgs/CameraInfo; none: camera_info beside the image topic (/left/camera_info)"
    )
    right_info_topic: str | None = Field(None, description="right CameraInfo; none: beside the right image topic")
    odometry_topic: str | None = Field(
        None,
        description="a nav_msgs/Odometry topic (REP-103 body pose) as the motion instead of stereo visual "
        "odometry; none: stereo odometry from the images",
    )
    images: Literal["auto", "raw", "rectified"] = Field(
        "auto",
        description="raw: undistort and rectify with each CameraInfo's K, D, R, P (as image_proc does); "
        "rectified: use the images as they come, calibrated by P; auto: rectified when the topic name says so "
        "(image_rect...) or when the CameraInfo's D is zero, R the identity and P's left 3x3 equal to K, else raw",
    )
    pair_slop_s: float = Field(
        0.005,
        gt=0,
        le=1.0,
        description="a left and a right image pair when their header stamps differ by at most this, s (stereo "
        "needs both taken at once; hardware-synchronised cameras give equal stamps)",
    )
    odometry_tolerance_s: float = Field(
        0.1,
        gt=0,
        le=10.0,
        description="with odometry_topic, an image pair's pose is interpolated between the odometry messages "
        "around its stamp, which must both lie this close to it, s",
    )
    odometry_wait_s: float = Field(
        0.05,
        ge=0,
        le=5.0,
        description="with odometry_topic, how long a pair waits for the odometry message after its stamp, s; a "
        "pair still without a pose is dropped and counted",
    )
    map_frame: str = Field("map", description="the corrected map's tf frame (REP-105)")
    odom_frame: str = Field("odom", description="the odometry's tf frame: map -> odom corrects the drift")
    robot_frame: str = Field(
        "camera_link",
        description="the robot frame NeoSLAM tracks (the left camera's centre, x forward, y left, z up): odom -> "
        "robot_frame is the odometry",
    )
    namespace: str = Field("/neoslam", description="prefix of the topics the node publishes (besides /tf)")
    sensor_depth: int = Field(
        5, gt=0, le=100, description="history kept per camera topic (sensor data QoS: best effort, keep last)"
    )
    status_period_s: float = Field(1.0, gt=0, le=3600, description="how often the status topic is published, s")
    path_period_s: float = Field(
        1.0,
        ge=0,
        le=3600,
        description="the path and the object markers are republished when the map changes (a keyframe, a loop), at "
        "most once in this many seconds, and at the end",
    )
    no_images_warning_s: float = Field(
        10.0,
        gt=0,
        le=3600,
        description="with no stereo pair this long after the start, one line names the topics subscribed to and "
        "those seen on the DDS domain",
    )
    resume_gap_s: float = Field(
        1.0,
        gt=0,
        le=3600,
        description="a gap between successive pairs' stamps longer than this (a camera or publisher that stopped and "
        "came back) restarts the stereo odometry's tracking from the new frame: the motion in the gap is unknown",
    )
    detect_ahead: bool = Field(
        False,
        description="detect objects in the next pair, in a thread of its own, while the current one is placed, "
        "tracked and mapped (the same frames give the same bytes): for a machine with cores to spare beside the "
        "network's perception.detector.threads; on two cores the two contend and a pair's latency grows (see "
        "benchmarks/live.py); false: one pair at a time",
    )
    stop_grace_s: float = Field(
        0.6,
        gt=0,
        le=60,
        description="after Ctrl-C or SIGTERM the node commits the map and writes its results; if that takes longer "
        "than this, s, it stops at once as any command does (the map keeps its last committed keyframe)",
    )

    @field_validator("left_topic", "right_topic", "left_info_topic", "right_info_topic", "odometry_topic", "namespace")
    @classmethod
    def _topic_name(cls, name: str | None) -> str | None:
        return None if name is None else _check_topic(name)

    @field_validator("map_frame", "odom_frame", "robot_frame")
    @classmethod
    def _frame_name(cls, name: str) -> str:
        if not name or name.startswith("/") or any(c.isspace() for c in name):
            raise ValueError(f"{name!r} is not a tf frame id (no leading slash, no spaces)")
        return name
