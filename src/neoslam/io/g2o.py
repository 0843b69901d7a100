"""The experience map's pose graph in g2o's text format, for other tools (g2o, GTSAM's readG2o, ...).

```
VERTEX_SE3:QUAT id x y z qx qy qz qw                          an experience's corrected pose T_world_robot
EDGE_SE3:QUAT source target x y z qx qy qz qw I11 I12 ... I66  a link's measured T_source_target and the upper
                                                               triangle (row by row) of its 6x6 information matrix
FIX 0                                                          the first experience defines the world frame
```

The information is diag(1 / sigma^2) of the sigmas the pose-graph back end gives the link
(`mapping.pose_graph.link_sigmas`: odometry links by the distance and time travelled, loop links by the closure's
accuracy),
in g2o's order: translation x, y, z, then rotation. The rotation block is per radian of rotation vector, as GTSAM's
readG2o and writeG2o take it (g2o itself measures the rotation error by the quaternion's vector part, half the
angle, so strictly its information would be four times larger). The robust kernel of loop links has no place in
the format and is left out. Quaternions have w >= 0; numbers are written with 17 significant digits, so a pose
reads back to the last bit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neoslam.geometry import quaternion_from_pose
from neoslam.mapping.pose_graph import link_sigmas

__all__ = ["write_g2o", "link_information"]

# link_sigmas orders the tangent as GTSAM does (rotation, then translation); g2o orders translation first.
_G2O_FROM_GTSAM_ORDER = np.array([3, 4, 5, 0, 1, 2])


def _numbers(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def _pose_numbers(pose: np.ndarray) -> str:
    return _numbers((*pose[:3, 3], *quaternion_from_pose(pose[None])[0]))


def link_information(link, config, noise=None) -> np.ndarray:
    """The 6x6 information matrix of a link in g2o's order (x, y, z, roll, pitch, yaw); `noise`: the odometry's per
    root second the back end weighs links with (None: by distance only)."""
    sigmas = link_sigmas(link, config, noise)[_G2O_FROM_GTSAM_ORDER]
    return np.diag(1.0 / sigmas**2)


def write_g2o(path: Path, experience_map) -> None:
    """experience_map.g2o: one vertex per experience (corrected pose), one edge per link in use (not the withdrawn),
    experience 0 fixed."""
    graph = experience_map.graph
    rows, cols = np.triu_indices(6)
    lines = [f"VERTEX_SE3:QUAT {index} {_pose_numbers(pose)}" for index, pose in enumerate(graph.poses)]
    for link in graph.live_links():
        information = link_information(link, experience_map.config, experience_map.backend.odometry_noise)[rows, cols]
        lines.append(
            f"EDGE_SE3:QUAT {link.source} {link.target} {_pose_numbers(link.relative)} {_numbers(information)}"
        )
    if len(graph):
        lines.append("FIX 0")
    path.write_text("".join(line + "\n" for line in lines))
