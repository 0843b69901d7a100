"""Map correction as in the paper (eq. 18) and NeuroSLAM: relax every link towards its measurement.

For each link e0 -> e1 with measured displacement l, the paper's Xr_t <- Xr_t + (Xr_t+1 − l)·c_f: the residual
between where e1 is and where e0 plus the link puts it is split, a share c_f moving e0 forward and the same share
moving e1 back; the yaws likewise. Sweeps run over the links in order (Gauss-Seidel, as NeuroSLAM), `passes` times.
Unlike NeuroSLAM, the link's displacement is applied un-mirrored (its quirk 1: a sign slip in the stored heading).

The state is NeuroSLAM's 4 degrees of freedom per experience (x, y, z, yaw); roll and pitch stay as the odometry
gave them. The sweep loops over plain Python floats: it is sequential by nature, and numpy scalars would be slower.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from neoslam.geometry import yaw_of
from neoslam.mapping.graph import MapGraph
from neoslam.types import Link

__all__ = ["LinkMeasurement", "link_measurement", "relax"]


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


LinkMeasurement = tuple[int, int, float, float, float, float]


def link_measurement(graph: MapGraph, link: Link) -> LinkMeasurement:
    """(source, target, dx, dy, dz, dyaw): the link's displacement in the source's yaw frame, height change and yaw
    change. Relaxation turns poses about the vertical only, so this stays valid as the map is corrected."""
    source = graph.poses[link.source]
    source_yaw = float(yaw_of(source))
    world = source[:3, :3] @ link.relative[:3, 3]
    c, s = math.cos(source_yaw), math.sin(source_yaw)
    dyaw = _wrap(float(yaw_of(source @ link.relative)) - source_yaw)
    return (link.source, link.target, c * world[0] + s * world[1], -s * world[0] + c * world[1], float(world[2]), dyaw)


def relax(graph: MapGraph, links: list[LinkMeasurement], correction_factor: float, passes: int) -> None:
    """`passes` relaxation sweeps over the links (eq. 18), correcting graph.poses in place (x, y, z, yaw)."""
    if not links or passes == 0:
        return
    x, y, z = (graph.poses[:, :3, 3].T).tolist()
    yaw = yaw_of(graph.poses).tolist()
    start_yaw = list(yaw)
    for _ in range(passes):
        for source, target, dx, dy, dz, dyaw in links:
            c, s = math.cos(yaw[source]), math.sin(yaw[source])
            rx = (x[target] - (x[source] + c * dx - s * dy)) * correction_factor
            ry = (y[target] - (y[source] + s * dx + c * dy)) * correction_factor
            rz = (z[target] - (z[source] + dz)) * correction_factor
            x[source] += rx
            y[source] += ry
            z[source] += rz
            x[target] -= rx
            y[target] -= ry
            z[target] -= rz
            turn = _wrap(yaw[target] - (yaw[source] + dyaw)) * correction_factor
            yaw[source] = _wrap(yaw[source] + turn)
            yaw[target] = _wrap(yaw[target] - turn)
    _write_back(graph, np.column_stack([x, y, z]), np.asarray(yaw) - np.asarray(start_yaw))


def _write_back(graph: MapGraph, positions: np.ndarray, yaw_change: np.ndarray) -> None:
    """New positions, and each orientation turned about the world's vertical by its yaw change."""
    turn = Rotation.from_euler("z", yaw_change[:, None]).as_matrix()
    graph.poses[:, :3, :3] = turn @ graph.poses[:, :3, :3]
    graph.poses[:, :3, 3] = positions
