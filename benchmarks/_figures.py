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
    """The loop detector's query time against the number of stored keyframes, a line per variant (loops, speed)."""
    rows = _rows(result, "speed")
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


# (benchmark, figure) -> (the function, the caption the page gives it)
FIGURES: dict[tuple[str, str], tuple[Callable[[dict[str, Any]], Figure], str]] = {
    ("navigation", "planning"): (planning_speed, "Route planning time against map size"),
    ("navigation", "deliveries"): (delivery_success, "Deliveries that arrived within 5 m"),
    ("loops", "speed"): (loop_query_speed, "Loop query time against stored keyframes"),
    ("live", "latency"): (live_latency, "Live node latency and drops against the camera's rate"),
    ("places", "recall"): (place_recall, "Loop recall at precision 1.0 by drive"),
}


def svg_text(figure: Figure) -> str:
    """The figure as SVG text, the same for the same figure (no date, fixed ids)."""
    with plt.rc_context(SVG_SETTINGS):
        buffer = io.StringIO()
        figure.tight_layout()
        figure.savefig(buffer, format="svg", metadata={"Date": None})
    plt.close(figure)
    return buffer.getvalue()
