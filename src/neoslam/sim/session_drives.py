"""Several sessions in one simulated world: parts of one drive recorded as separate runs, each from its own start.

A robot that maps a town on one day and drives part of it again on another starts each session where it stands,
knowing nothing of its pose relative to the earlier map. `session_recordings` cuts a true trajectory into spans of
frames; all spans see one world of objects, placed once along the whole trajectory (with the config's seed, as
`simulate` would place it), and each span is re-based so that its session starts at the identity: its truth is
inv(T_start) @ truth[start:stop] and its world the shared world moved by inv(T_start) (`World.moved`). Each session
draws its own odometry and detection noise (its own seed), so two sessions over the same street see the same
objects at the same true places but measure them independently. Timestamps are kept as they are in `truth` (a
moving object is where the shared world has it at that time).

`SessionRecording.start_pose` (T_world_sessionstart) is ground truth, for evaluation only: it takes a session's
poses and objects back to the frame of the whole trajectory. A session's frame is its first pose's, roll and pitch
included, as a camera's odometry frame is: a session that starts on a slope or a cambered road (KITTI 05's frame 1200
has 2.9 degrees of roll) has its z axis tilted against the other sessions' by that much.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neoslam.config import SimulatorConfig
from neoslam.geometry import invert_pose
from neoslam.sim.simulator import SimulatedRecording, simulate, world_for
from neoslam.types import Trajectory

__all__ = ["SessionRecording", "session_recordings"]

MIN_SESSION_FRAMES = 2  # odometry needs a step


@dataclass(frozen=True)
class SessionRecording:
    """One session's recording, in its own frame (its first true pose is the identity), and where it started."""

    recording: SimulatedRecording
    start_pose: np.ndarray  # (4, 4) T_world_sessionstart in the frame of the whole trajectory; evaluation only
    span: tuple[int, int]  # frames [start, stop) of the whole trajectory

    def to_world(self, poses: np.ndarray) -> np.ndarray:
        """(n, 4, 4) poses of this session's frame in the frame of the whole trajectory."""
        return self.start_pose @ poses


def session_recordings(
    truth: Trajectory, spans: list[tuple[int, int]], config: SimulatorConfig, seeds: list[int], name: str
) -> list[SessionRecording]:
    """One recording per span [start, stop) of `truth`, all in the world placed along the whole of `truth` with
    `config.seed`, each re-based to start at the identity, with the odometry and detection noise of its own seed
    (`config` with seed = seeds[k]). Deterministic in `config.seed` and `seeds`."""
    if len(spans) != len(seeds):
        raise ValueError(f"{len(spans)} spans but {len(seeds)} seeds")
    for start, stop in spans:
        if not 0 <= start < stop <= len(truth) or stop - start < MIN_SESSION_FRAMES:
            raise ValueError(f"span ({start}, {stop}) is not a run of at least two of the {len(truth)} frames")
    world = world_for(truth, config)
    sessions = []
    for k, ((start, stop), seed) in enumerate(zip(spans, seeds, strict=True)):
        start_pose = truth.poses[start].copy()
        to_session = invert_pose(start_pose)
        part = Trajectory(truth.timestamps[start:stop].copy(), to_session @ truth.poses[start:stop])
        part.poses[0] = np.eye(4)  # exactly, not to rounding: odometry starts there
        session_config = config.model_copy(update={"seed": seed})
        source = f"{name} frames {start}-{stop} (session {k + 1}; world seed {config.seed}, noise seed {seed})"
        recording = simulate(part, session_config, f"{name}-session{k + 1}", source, world=world.moved(to_session))
        sessions.append(SessionRecording(recording, start_pose, (start, stop)))
    return sessions
