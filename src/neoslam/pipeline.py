"""NeoSLAM: `step(frame)` reads as the paper's steps; `run(frames)` drives it with a progress bar.

At this stage the estimate is the odometry (path integration of the visual odometry); the grid cells,
object keyframes, loop closure and the experience map plug in here without changing the CLI.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from neoslam.config import NeoSLAMConfig
from neoslam.mapping.object_map import MapObject, ObjectMap
from neoslam.types import Frame, LoopClosure, Trajectory

__all__ = ["NeoSLAM", "RunResult", "run"]


@dataclass(frozen=True)
class RunResult:
    estimate: Trajectory  # corrected trajectory, one pose per input frame
    odometry: Trajectory
    objects: list[MapObject]
    loop_closures: list[LoopClosure]
    frame_times_s: np.ndarray  # wall time of each step


class NeoSLAM:
    """The whole system, one frame at a time."""

    def __init__(self, config: NeoSLAMConfig) -> None:
        self.config = config
        self.object_map = ObjectMap(config.object_map)
        self.loop_closures: list[LoopClosure] = []
        self._timestamps: list[float] = []
        self._estimate: list[np.ndarray] = []
        self._odometry: list[np.ndarray] = []

    def step(self, frame: Frame) -> np.ndarray:
        """Process one frame; returns the current pose estimate T_world_robot."""
        pose = self._integrate_path(frame)
        self.object_map.add(pose, frame.observations)
        self._timestamps.append(frame.timestamp)
        self._odometry.append(frame.odometry_pose)
        self._estimate.append(pose)
        return pose

    def _integrate_path(self, frame: Frame) -> np.ndarray:
        # Path integration is the odometry itself until the grid cells and the experience map land.
        return frame.odometry_pose

    def result(self, frame_times_s: np.ndarray) -> RunResult:
        stamps = np.asarray(self._timestamps)
        return RunResult(
            estimate=Trajectory(stamps, np.asarray(self._estimate).reshape(-1, 4, 4)),
            odometry=Trajectory(stamps, np.asarray(self._odometry).reshape(-1, 4, 4)),
            objects=self.object_map.objects(),
            loop_closures=list(self.loop_closures),
            frame_times_s=frame_times_s,
        )


def run(frames: Iterable[Frame], config: NeoSLAMConfig, total: int | None = None, progress: bool = True) -> RunResult:
    """Drive NeoSLAM over frames; wall time per frame is recorded for the timing block of metrics.json."""
    slam = NeoSLAM(config)
    times = []
    for frame in tqdm(frames, total=total, desc="neoslam", unit="frame", disable=not progress):
        start = time.perf_counter()
        slam.step(frame)
        times.append(time.perf_counter() - start)
    return slam.result(np.asarray(times))
