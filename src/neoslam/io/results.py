"""The results folder of a run (DESIGN.md): trajectories, object map, loop closures, metrics, config, plots."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.config import NeoSLAMConfig, dump_config
from neoslam.errors import InputError
from neoslam.geometry import pose_from_quaternion, quaternion_from_pose
from neoslam.io.tables import numeric_column, read_table, write_table
from neoslam.io.trajectory_files import QUATERNION_NORM_TOLERANCE, write_kitti, write_tum
from neoslam.mapping.object_map import MapObject
from neoslam.text import read_text
from neoslam.types import LoopClosure, Trajectory

__all__ = [
    "KEYFRAME_FRAMES",
    "LOOP_COLUMNS",
    "OBJECT_COLUMNS",
    "read_keyframe_frames",
    "write_keyframe_frames",
    "write_trajectories",
    "write_loop_closures",
    "write_objects",
    "write_metrics",
    "write_config",
    "read_loop_closures",
    "write_object_vector_cells",
    "write_experience_map",
]

LOOP_COLUMNS = (
    "query_frame", "match_frame", "query_keyframe", "match_keyframe", "score", "matched_objects",
    "tx", "ty", "tz", "qx", "qy", "qz", "qw", "session", "match_session",
)  # fmt: skip
LOOP_COLUMNS_WITHOUT_SESSIONS = LOOP_COLUMNS[:-2]  # as written before maps were kept over sessions
OBJECT_COLUMNS = ("id", "label", "x", "y", "z", "observations", "moving")
KEYFRAME_FRAMES = "keyframe_frames.csv"  # beside loop_closures.csv: the frames loop recall is counted over
KEYFRAME_FRAME_COLUMNS = ("frame",)


def write_trajectories(folder: Path, trajectories: dict[str, Trajectory]) -> None:
    """name_tum.txt and name_kitti.txt for each trajectory (for example trajectory, odometry, groundtruth)."""
    for name, trajectory in trajectories.items():
        write_tum(folder / f"{name}_tum.txt", trajectory)
        write_kitti(folder / f"{name}_kitti.txt", trajectory)


def write_loop_closures(path: Path, closures: list[LoopClosure], sessions: list[tuple[int, int]] | None = None) -> None:
    """One row per accepted closure; the relative transform T_match_query as translation and quaternion; the
    session of each keyframe (`sessions`, default 1 and 1: match_frame is a frame of the match's session)."""
    rows = []
    for c, (session, match_session) in zip(closures, sessions or [(1, 1)] * len(closures), strict=True):
        quaternion = quaternion_from_pose(c.relative_pose[None])[0]
        rows.append(
            [c.query_frame, c.match_frame, c.query_keyframe, c.match_keyframe, f"{c.score:.6f}", c.n_matches]
            + [f"{v:.6f}" for v in (*c.relative_pose[:3, 3], *quaternion)]
            + [session, match_session]
        )
    write_table(path, LOOP_COLUMNS, rows)


def write_objects(path: Path, objects: list[MapObject], moving: list[MapObject] | None = None) -> None:
    """The map's objects (moving 0, their map ids), then the moving objects where they were last seen (moving 1,
    numbered on from the map's largest id in the order the motion detector tracked them): an id names one row."""
    first_moving = max((o.id for o in objects), default=-1) + 1
    rows = [[o.id, o.label, *(f"{v:.4f}" for v in o.position), o.observations, 0] for o in objects]
    rows += [
        [first_moving + k, o.label, *(f"{v:.4f}" for v in o.position), o.observations, 1]
        for k, o in enumerate(moving or [])
    ]
    write_table(path, OBJECT_COLUMNS, rows)


def write_object_vector_cells(folder: Path, cells) -> None:
    """The trained OVCN (ovcn.pt, loaded by ObjectVectorCells.load) and its loss per epoch (ovcn_loss.csv)."""
    cells.save(folder / "ovcn.pt")
    rows = [[epoch, f"{loss:.8f}"] for epoch, loss in enumerate(cells.loss_history, start=1)]
    write_table(folder / "ovcn_loss.csv", ("epoch", "loss"), rows)


def _pose_record(pose: np.ndarray) -> dict[str, float]:
    quaternion = quaternion_from_pose(pose[None])[0]
    values = (*pose[:3, 3], *quaternion)
    return {k: round(float(v), 6) for k, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"), values, strict=True)}


def write_experience_map(path: Path, experience_map) -> None:
    """experience_map.json: experiences (cells, corrected and odometry pose, keyframe) and links (eq. 15-16), each
    with whether it was withdrawn (a loop link the optimised map disagreed with: kept for the record, out of the
    map)."""
    graph = experience_map.graph
    withdrawn = set(graph.withdrawn)
    experiences = [
        {
            "id": e.id,
            "frame": e.frame_index,
            "keyframe": e.keyframe_id,
            "grid_cell": [round(float(v), 4) for v in e.grid_cell],
            "head_direction_cell": round(float(e.head_direction), 4),
            "pose": _pose_record(graph.poses[e.id]),
            "odometry_pose": _pose_record(e.pose),
            "session": e.session,
        }
        for e in experience_map.experiences
    ]
    links = [
        {
            "source": k.source,
            "target": k.target,
            "kind": k.kind,
            "distance_m": round(k.distance_m, 4),
            "duration_s": round(k.duration_s, 4),
            "relative": _pose_record(k.relative),
            "withdrawn": index in withdrawn,
        }  # fmt: skip
        for index, k in enumerate(graph.links)
    ]
    payload = {"backend": experience_map.config.backend, "experiences": experiences, "links": links}
    path.write_text(json.dumps(payload, separators=(",", ":")) + "\n")


def _json_ready(value: Any) -> Any:
    """The value with every NaN or infinite float replaced by None: JSON has neither (an ATE of 1e300-metre
    trajectories overflows to inf), and null is what a figure the data cannot support is written as."""
    if isinstance(value, dict):
        return {key: _json_ready(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(item) for item in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_metrics(path: Path, metrics: dict[str, Any]) -> None:
    path.write_text(json.dumps(_json_ready(metrics), indent=2, allow_nan=False) + "\n")


def write_config(path: Path, config: NeoSLAMConfig) -> None:
    path.write_text(dump_config(config))


def _check_loop_row(values: dict[str, np.ndarray], k: int, frames: int | None) -> str | None:
    """The problem of row k of loop_closures.csv, if any: counts are integers, frames lie in the trajectory,
    the rotation is a unit quaternion."""
    for name in ("query_frame", "match_frame", "query_keyframe", "match_keyframe", "matched_objects"):
        value = values[name][k]
        if value != int(value) or value < 0:
            return f"column {name}: {value:g} is not a non-negative integer"
    for name in ("query_frame", "match_frame"):
        if frames is not None and values[name][k] >= frames:
            return f"column {name}: frame {values[name][k]:g} is beyond the {frames} poses of the ground truth"
    norm = math.hypot(*(values[c][k] for c in ("qx", "qy", "qz", "qw")))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        return "zero quaternion" if norm == 0 else f"non-unit quaternion (norm {norm:.3g})"
    return None


def read_loop_closures(path: Path, frames: int | None = None) -> list[LoopClosure]:
    """Read loop_closures.csv back (for `neoslam evaluate --loops`): the closures within one session (a closure
    with an earlier session's keyframe names a frame of that session). With `frames`, the length of the trajectory
    the closures' frames index, a frame beyond it is refused with its line."""
    columns = LOOP_COLUMNS
    if read_text(path).lstrip("\ufeff").startswith(",".join(LOOP_COLUMNS_WITHOUT_SESSIONS) + "\n"):
        columns = LOOP_COLUMNS_WITHOUT_SESSIONS
    rows = read_table(path, columns)
    values = {name: numeric_column(path, rows, columns, name) for name in columns}
    closures = []
    for k in range(len(rows)):
        if "session" in values and values["session"][k] != values["match_session"][k]:
            continue
        problem = _check_loop_row(values, k, frames)
        if problem is not None:
            raise InputError(path, problem, line=int(rows.lines[k]))
        translation = [values[c][k] for c in ("tx", "ty", "tz")]
        quaternion = np.array([values[c][k] for c in ("qx", "qy", "qz", "qw")])
        quaternion /= np.linalg.norm(quaternion)
        closures.append(
            LoopClosure(
                query_frame=int(values["query_frame"][k]),
                match_frame=int(values["match_frame"][k]),
                query_keyframe=int(values["query_keyframe"][k]),
                match_keyframe=int(values["match_keyframe"][k]),
                score=float(values["score"][k]),
                n_matches=int(values["matched_objects"][k]),
                relative_pose=pose_from_quaternion(np.array(translation), quaternion)[0],
            )
        )
    return closures


def write_keyframe_frames(path: Path, frames: np.ndarray) -> None:
    """The frames at which the run made or recognised a keyframe (only they can close a loop): the query frames of
    metrics.json's loop recall, and of `neoslam evaluate --loops` when this file is beside the closures."""
    write_table(path, KEYFRAME_FRAME_COLUMNS, [[int(frame)] for frame in frames])


def read_keyframe_frames(path: Path, frames: int | None = None) -> np.ndarray:
    """keyframe_frames.csv back: each frame a non-negative integer within the `frames` poses of the ground truth."""
    rows = read_table(path, KEYFRAME_FRAME_COLUMNS)
    values = numeric_column(path, rows, KEYFRAME_FRAME_COLUMNS, "frame")
    for k, value in enumerate(values):
        if value != int(value) or value < 0:
            raise InputError(path, f"column frame: {value:g} is not a non-negative integer", line=int(rows.lines[k]))
        if frames is not None and value >= frames:
            problem = f"column frame: frame {value:g} is beyond the {frames} poses of the ground truth"
            raise InputError(path, problem, line=int(rows.lines[k]))
    return values.astype(int)
