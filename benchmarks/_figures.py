"""The figures of the benchmark pages, drawn from the stored results' tables (benchmarks/render.py puts them into the
pages as it puts the tables). Each figure is a function of a stored result giving a matplotlib figure; FIGURES
names them `(benchmark, figure)`. They are written as SVG with no date and a fixed id salt, so that the same
result gives the same file."""

from __future__ import annotations

import io
from collections.abc import Callable
from typing import Any

import matplotlib

matplotlib.use("Agg")  # headless: files only
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

__all__ = ["FIGURES", "Figure", "svg_text"]

SIZE = (6.4, 3.8)  # inches
SVG_SETTINGS = {"svg.hashsalt": "neoslam-benchmarks", "svg.fonttype": "none"}  # ids and text stable


def _rows(result: dict[str, Any], table: str) -> list[dict[str, Any]]:
    tables = result.get("tables", {})
    if table not in tables:
        raise KeyError(f"{result.get('benchmark')}: no table {table!r} in the stored result for its figure")
    return tables[table]["rows"]


def _axes(title: str, xlabel: str, ylabel: str) -> tuple[Figure, Any]:
    figure, axes = plt.subplots(figsize=SIZE)
    axes.set(title=title, xlabel=xlabel, ylabel=ylabel)
    axes.grid(alpha=0.3, which="both")
    return figure, axes


def planning_speed(result: dict[str, Any]) -> Figure:
    """Route planning time against the map's size (navigation, part speed)."""
    rows = _rows(result, "planning")
    sizes = [r["experiences"] for r in rows]
    figure, axes = _axes("Route planning against map size", "experiences in the map", "ms")
    axes.plot(sizes, [r["plan_ms_median"] for r in rows], "o-", label="a plan, median")
    axes.plot(sizes, [r["plan_ms_p95"] for r in rows], "o--", label="a plan, 95th percentile")
    axes.plot(sizes, [r["graph_ms"] for r in rows], "s:", label="the graph, once per map")
    axes.axhline(10.0, color="tab:red", linewidth=0.8, label="target: 10 ms (median)")
    axes.set_xscale("log")
    axes.legend(fontsize=8)
    return figure


def loop_query_speed(result: dict[str, Any]) -> Figure:
    """The loop detector's query time against the number of stored keyframes, a line per variant (loops, speed), on
    the map of distinct places."""
    rows = [r for r in _rows(result, "speed") if r.get("map", "distinct") == "distinct"]
    figure, axes = _axes("Loop query against stored keyframes", "stored keyframes", "ms a query (median)")
    variants = sorted({(r["eigenvector"], r["scope"]) for r in rows})
    for eigenvector, scope in variants:
        chosen = sorted((r for r in rows if (r["eigenvector"], r["scope"]) == (eigenvector, scope)),
                        key=lambda r: r["map_size"])  # fmt: skip
        axes.plot([r["map_size"] for r in chosen], [r["query_ms_median"] for r in chosen], "o-",
                  label=f"{eigenvector} eigenvector, {scope}")  # fmt: skip
    axes.set_xscale("log")
    axes.legend(fontsize=8)
    return figure


def live_latency(result: dict[str, Any]) -> Figure:
    """The live node's latency and the frames it mapped against the rate the camera sent at (live, sweep)."""
    rows = sorted(_rows(result, "sweep"), key=lambda r: r["rate_hz"])
    rates = [r["rate_hz"] for r in rows]
    figure, axes = _axes("Live node against the camera's rate", "pairs sent a second", "latency, ms")
    axes.plot(rates, [r["latency_ms_median"] for r in rows], "o-", label="latency, median")
    axes.plot(rates, [r["latency_ms_p95"] for r in rows], "o--", label="latency, 95th percentile")
    share = axes.twinx()
    share.plot(rates, [r["dropped"] for r in rows], "s:", color="tab:red", label="pairs dropped")
    share.set_ylabel("pairs dropped")
    lines = axes.get_legend_handles_labels()
    more = share.get_legend_handles_labels()
    axes.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="upper left")
    return figure


def place_recall(result: dict[str, Any]) -> Figure:
    """Loop recall at precision 1.0 by drive: the median over the seeds and the lowest seed (places, pipeline)."""
    rows = _rows(result, "pipeline")
    names = [str(r["sequence"]) for r in rows]
    figure, axes = _axes("Loop recall at precision 1.0 (simulated, real profile)", "drive", "recall")
    axes.bar(names, [r["recall_median"] for r in rows], color="tab:blue", label="median over the seeds")
    axes.plot(names, [r["recall_min"] for r in rows], "v", color="black", label="lowest seed")
    axes.set_ylim(0.0, 1.0)
    axes.legend(fontsize=8, loc="lower right")
    return figure


def delivery_success(result: dict[str, Any]) -> Figure:
    """Deliveries that arrived within 5 m, by map and by kind of goal (navigation, part deliveries)."""
    maps = _rows(result, "deliveries")
    kinds = [r for r in _rows(result, "deliveries_by_goal") if r["deliveries"]]
    rows = maps + kinds
    names = [str(r["map"]) for r in rows]
    figure, axes = _axes("Closed-loop deliveries (simulated)", "", "arrived within 5 m, %")
    colours = ["tab:blue"] * len(maps) + ["tab:green"] * len(kinds)
    axes.bar(names, [r["success_pct"] for r in rows], color=colours)
    axes.axhline(99.0, color="tab:red", linewidth=0.8, label="target: 99 %")
    axes.set_ylim(min(80.0, min(r["success_pct"] for r in rows) - 5), 100.5)
    axes.tick_params(axis="x", labelrotation=30)
    axes.legend(fontsize=8, loc="lower right")
    return figure


CLASS_COLOURS = {"car": "tab:blue", "truck": "tab:purple", "person": "tab:orange", "bicycle": "tab:green"}
DRIVE_COLUMNS = 3


def drive_trajectories(result: dict[str, Any]) -> Figure:
    """Each drive from above: the ground truth, the odometry and the corrected map's trajectory (aligned to the truth
    as the ATE is), the closures accepted (true or false) and the map's objects by class (trajectories)."""
    drives = result.get("figures", {}).get("drives", [])
    if not drives:
        raise KeyError("trajectories: no drives in the stored result for its figure")
    columns = DRIVE_COLUMNS if len(drives) % DRIVE_COLUMNS else DRIVE_COLUMNS + 1  # a cell left for the legend
    rows = -(-len(drives) // columns)
    figure, grid = plt.subplots(rows, columns, figsize=(4.0 * columns, 3.8 * rows), squeeze=False)
    for axes in grid.ravel()[len(drives) :]:
        axes.axis("off")
    for axes, drive in zip(grid.ravel(), drives, strict=False):
        _draw_drive(axes, drive)
    handles, labels = _legend_entries(grid.ravel()[: len(drives)])
    grid.ravel()[len(drives)].legend(handles, labels, loc="center", fontsize=9, frameon=False, markerscale=3)
    return figure


PATH_STYLES = {  # path -> (colour, line, legend)
    "truth": ("black", "-", "ground truth"),
    "odometry": ("tab:gray", "--", "odometry"),
    "corrected": ("tab:red", "-", "corrected map"),
}
CLOSURE_STYLES = {True: ("o", "tab:green", "closure (true)"), False: ("x", "magenta", "closure (false)")}


def _draw_xy(axes: Any, points: list[list[float]], style: str, **options: Any) -> None:
    if points:
        axes.plot([p[0] for p in points], [p[1] for p in points], style, **options)


def _draw_drive(axes: Any, drive: dict[str, Any]) -> None:
    objects, labels = drive["object_points"], drive["object_labels"]
    for label in sorted(set(labels)):
        mine = [point for point, other in zip(objects, labels, strict=True) if other == label]
        _draw_xy(axes, mine, ".", markersize=2, color=CLASS_COLOURS.get(label, "tab:gray"), label=f"object: {label}")
    for name, (colour, line, legend) in PATH_STYLES.items():
        _draw_xy(axes, drive["paths"][name], line, color=colour, linewidth=1.0, label=legend)
    for verdict, (marker, colour, legend) in CLOSURE_STYLES.items():
        chosen = [p for p, ok in zip(drive["closure_points"], drive["closure_true"], strict=True) if ok is verdict]
        _draw_xy(axes, chosen, marker, color=colour, markersize=3, fillstyle="none", label=legend)
    ate = drive["ate_m"]
    shown = "-" if ate is None else f"{ate:.2f} m"  # a drive the ATE cannot align
    axes.set_title(f"{drive['drive']}: ATE {shown}, {drive['closures']} closures", fontsize=9)
    axes.set_aspect("equal", adjustable="datalim")
    axes.tick_params(labelsize=7)
    axes.grid(alpha=0.3)


def _legend_entries(axes_list: Any) -> tuple[list[Any], list[str]]:
    """Every line drawn in any of the axes, once per label."""
    seen: dict[str, Any] = {}
    for axes in axes_list:
        for handle, label in zip(*axes.get_legend_handles_labels(), strict=True):
            seen.setdefault(label, handle)
    order = sorted(seen, key=lambda label: (label.startswith("object"), label.startswith("closure"), label))
    return [seen[label] for label in order], order


# (benchmark, figure) -> (the function, the caption the page gives it)
FIGURES: dict[tuple[str, str], tuple[Callable[[dict[str, Any]], Figure], str]] = {
    ("navigation", "planning"): (planning_speed, "Route planning time against map size"),
    ("navigation", "deliveries"): (delivery_success, "Deliveries that arrived within 5 m"),
    ("loops", "speed"): (loop_query_speed, "Loop query time against stored keyframes"),
    ("live", "latency"): (live_latency, "Live node latency and drops against the camera's rate"),
    ("places", "recall"): (place_recall, "Loop recall at precision 1.0 by drive"),
    ("trajectories", "drives"): (drive_trajectories, "The drives from above: truth, odometry, corrected map, closures"),
}


def svg_text(figure: Figure) -> str:
    """The figure as SVG text, the same for the same figure (no date, fixed ids)."""
    with plt.rc_context(SVG_SETTINGS):
        buffer = io.StringIO()
        figure.tight_layout()
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    plt.close(figure)
    return buffer.getvalue()
