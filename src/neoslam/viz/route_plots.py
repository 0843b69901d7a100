"""A route over the map as a PNG (`neoslam route`): the corrected experience graph (every link), the route on it,
the objects labelled by class and id (stale ones crossed out in grey), the start and the goal."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

from neoslam.navigation import ObjectStatus, Route  # noqa: E402
from neoslam.viz.plots import DPI, LABEL_COLOURS  # noqa: E402

__all__ = ["MAX_LABELLED", "plot_route"]

MAX_LABELLED = 150  # more objects than this: only the goal's is labelled (the labels would hide the map)
STALE_COLOUR = "0.55"


def plot_route(path: Path, positions: np.ndarray, pairs: np.ndarray, route: Route, objects: list[ObjectStatus]) -> None:
    """Top view of the map's links (`pairs` of experience ids into `positions`, map frame), the route, the objects,
    the start and the goal."""
    figure, axes = plt.subplots(figsize=(8, 7))
    segments = positions[pairs][:, :, :2] if len(pairs) else np.zeros((0, 2, 2))
    axes.add_collection(LineCollection(segments, colors="0.75", linewidths=0.6, label="map links"))
    axes.plot(*positions[:, :2].T, ".", color="0.6", markersize=1.5)
    _objects(axes, objects, route)
    axes.plot(*route.path[:, :2].T, color="tab:red", linewidth=2.4, zorder=4, label="route")
    start = route.positions[0]
    axes.plot(*start[:2], "^", color="tab:green", markersize=11, zorder=5, label=f"start (experience {route.start})")
    goal = route.goal
    axes.plot(*goal.target[:2], "*", color="tab:red", markersize=16, zorder=6, label=f"goal: {goal.text}")
    if goal.offset_m > 0:
        axes.plot(*goal.position[:2], "o", color="tab:red", markersize=6, zorder=5, label="route end")
    time = "" if route.expected_time_s is None else f", about {route.expected_time_s:.0f} s"
    axes.set(
        xlabel="x [m] (map frame)",
        ylabel="y [m]",
        title=f"Route to {goal.text}: {route.length_m:.0f} m, {len(route)} waypoints{time}",
    )
    axes.set_aspect("equal", adjustable="datalim")
    axes.autoscale_view()
    axes.grid(alpha=0.3)
    axes.legend(loc="best", fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def _objects(axes, objects: list[ObjectStatus], route: Route) -> None:
    """Each object at its position, coloured by class; stale ones as grey crosses; labels `car 12`."""
    goal_object = route.goal.object.id if route.goal.object is not None else None
    labelled = len(objects) <= MAX_LABELLED
    for label in sorted({o.label for o in objects}):
        fresh = np.array([o.position[:2] for o in objects if o.label == label and not o.stale]).reshape(-1, 2)
        if len(fresh):
            axes.plot(*fresh.T, "o", markersize=4, color=LABEL_COLOURS.get(label, "tab:brown"), label=label)
    stale = np.array([o.position[:2] for o in objects if o.stale]).reshape(-1, 2)
    if len(stale):
        axes.plot(*stale.T, "x", markersize=6, color=STALE_COLOUR, label="stale object")
    for found in objects:
        if labelled or found.id == goal_object:
            colour = STALE_COLOUR if found.stale else "0.15"
            axes.annotate(
                found.describe(),
                found.position[:2],
                fontsize=6,
                color=colour,
                xytext=(3, 3),
                textcoords="offset points",
            )
