"""The results folder of a run (DESIGN.md): trajectories, object map, loop closures, metrics, config, plots."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.config import NeoSLAMConfig, dump_config
from neoslam.geometry import pose_from_quaternion, quaternion_from_pose
from neoslam.io.tables import numeric_column, read_table, write_table
from neoslam.io.trajectory_files import write_kitti, write_tum
from neoslam.mapping.object_map import MapObject
from neoslam.types import LoopClosure, Trajectory

__all__ = [
    "LOOP_COLUMNS",
    "OBJECT_COLUMNS",
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
    "tx", "ty", "tz", "qx", "qy", "qz", "qw",
)  # fmt: skip
OBJECT_COLUMNS = ("id", "label", "x", "y", "z", "observations")


def write_trajectories(folder: Path, trajectories: dict[str, Trajectory]) -> None:
    """name_tum.txt and name_kitti.txt for each trajectory (for example trajectory, odometry, groundtruth)."""
    for name, trajectory in trajectories.items():
        write_tum(folder / f"{name}_tum.txt", trajectory)
        write_kitti(folder / f"{name}_kitti.txt", trajectory)


def write_loop_closures(path: Path, closures: list[LoopClosure]) -> None:
    """One row per accepted closure; the relative transform T_match_query as translation and quaternion."""
    rows = []
    for c in closures:
        quaternion = quaternion_from_pose(c.relative_pose[None])[0]
        rows.append(
            [c.query_frame, c.match_frame, c.query_keyframe, c.match_keyframe, f"{c.score:.6f}", c.n_matches]
            + [f"{v:.6f}" for v in (*c.relative_pose[:3, 3], *quaternion)]
        )
    write_table(path, LOOP_COLUMNS, rows)


def write_objects(path: Path, objects: list[MapObject]) -> None:
    rows = [[o.id, o.label, *(f"{v:.4f}" for v in o.position), o.observations] for o in objects]
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
    """experience_map.json: experiences (cells, corrected and odometry pose, keyframe) and links (eq. 15-16)."""
    graph = experience_map.graph
    experiences = [
        {
            "id": e.id,
            "frame": e.frame_index,
            "keyframe": e.keyframe_id,
            "grid_cell": [round(float(v), 4) for v in e.grid_cell],
            "head_direction_cell": round(float(e.head_direction), 4),
            "pose": _pose_record(graph.poses[e.id]),
            "odometry_pose": _pose_record(e.pose),
        }
        for e in experience_map.experiences
    ]
    links = [
        {
            "source": k.source,
            "target": k.target,
            "kind": k.kind,
            "distance_m": round(k.distance_m, 4),
            "relative": _pose_record(k.relative),
        }  # fmt: skip
        for k in graph.links
    ]
    payload = {"backend": experience_map.config.backend, "experiences": experiences, "links": links}
    path.write_text(json.dumps(payload, separators=(",", ":")) + "\n")


def write_metrics(path: Path, metrics: dict[str, Any]) -> None:
    path.write_text(json.dumps(metrics, indent=2, allow_nan=False) + "\n")


def write_config(path: Path, config: NeoSLAMConfig) -> None:
    path.write_text(dump_config(config))


def read_loop_closures(path: Path) -> list[LoopClosure]:
    """Read loop_closures.csv back (for `neoslam evaluate --loops`)."""
    rows = read_table(path, LOOP_COLUMNS)
    values = {name: numeric_column(path, rows, LOOP_COLUMNS, name) for name in LOOP_COLUMNS}
    closures = []
    for k in range(len(rows)):
        translation = [values[c][k] for c in ("tx", "ty", "tz")]
        quaternion = [values[c][k] for c in ("qx", "qy", "qz", "qw")]
        closures.append(
            LoopClosure(
                query_frame=int(values["query_frame"][k]),
                match_frame=int(values["match_frame"][k]),
                query_keyframe=int(values["query_keyframe"][k]),
                match_keyframe=int(values["match_keyframe"][k]),
                score=float(values["score"][k]),
                n_matches=int(values["matched_objects"][k]),
                relative_pose=pose_from_quaternion(np.array(translation), np.array(quaternion))[0],
            )
        )
    return closures
