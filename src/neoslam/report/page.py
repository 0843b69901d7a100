"""The report page: one HTML file with everything in it (figures as data: URIs, the style inline, no script, no
external address), one column a run. The same folders give the same bytes."""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Sequence
from typing import Any

from neoslam.config import NeoSLAMConfig, dump_config
from neoslam.report.results import FIGURES, RunFolder, flatten
from neoslam.text import load_yaml

__all__ = ["METRIC_ROWS", "render_report"]

# The metrics table: a label and where the figure lies in metrics.json (dotted); absent ones show as a dash.
METRIC_ROWS = (
    ("dataset", "dataset"),
    ("frames", "frames"),
    ("ATE corrected, m", "ate_rmse_m.corrected"),
    ("ATE odometry, m", "ate_rmse_m.odometry"),
    ("alignment", "trajectory.alignment"),
    ("RPE corrected, m", "trajectory.corrected.rpe_translation_rmse_m"),
    ("RPE corrected, deg", "trajectory.corrected.rpe_rotation_rmse_deg"),
    ("KITTI drift corrected, %", "trajectory.corrected.kitti_translation_percent"),
    ("loop closures accepted", "loops.accepted"),
    ("loop precision", "loops.precision"),
    ("loop recall", "loops.recall"),
    ("loop recall at precision 1", "loops.recall_at_full_precision"),
    ("loop recall over", "loops.recall_over"),
    ("keyframes", "keyframes"),
    ("experiences", "experience_map.experiences"),
    ("links", "experience_map.links"),
    ("back end", "experience_map.backend"),
    ("objects in the map", "objects"),
    ("moving objects", "moving_objects"),
    ("map session", "session.id"),
    ("relocalised at frame", "session.relocalised_frame"),
    ("goal", "guidance.resolved"),
    ("guidance", "guidance.state"),
)
ABSENT = "–"
STYLE = """
body { font-family: system-ui, sans-serif; margin: 1.5em; color: #222; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; } td.number { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 0; } figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; margin-bottom: 0.3em; }
.figures td { width: calc(100% / var(--runs)); }
"""


def _value(metrics: dict[str, Any], path: str) -> Any:
    value: Any = metrics
    for key in path.split("."):
        if not isinstance(value, dict) or key not in value:
            return None
        value = value[key]
    return value


def _cell(value: Any) -> str:
    if value is None:
        return f"<td>{ABSENT}</td>"
    if isinstance(value, list | dict):
        return f"<td>{html.escape(_canonical(value))}</td>"
    if isinstance(value, bool) or not isinstance(value, int | float):
        return f"<td>{html.escape(str(value))}</td>"
    text = f"{value:,}" if isinstance(value, int) else f"{value:.4g}"
    return f'<td class="number">{text}</td>'


def _canonical(value: Any) -> str:
    """A setting as comparable text: mappings with sorted keys (a YAML file may order them otherwise)."""
    return json.dumps(value, sort_keys=True, default=str)


def _header(runs: Sequence[RunFolder], first: str) -> str:
    names = "".join(f"<th>{html.escape(run.name)}</th>" for run in runs)
    return f"<tr><th>{html.escape(first)}</th>{names}</tr>"


def _metrics_table(runs: Sequence[RunFolder]) -> str:
    rows = []
    for label, path in METRIC_ROWS:
        values = [_value(run.metrics, path) for run in runs]
        if all(v is None for v in values) and "." in path:
            continue  # a block no run has (no map session, no goal)
        rows.append(f"<tr><th>{html.escape(label)}</th>{''.join(_cell(v) for v in values)}</tr>")
    return f"<table>{_header(runs, 'metric')}{''.join(rows)}</table>"


def _timing_table(runs: Sequence[RunFolder]) -> str:
    """Every figure of the timing and perception blocks (ms by stage, frames a second)."""
    blocks = [flatten({"slam": run.metrics.get("timing", {}), "perception": run.metrics.get("perception", {})})
              for run in runs]  # fmt: skip
    keys = sorted({key for block in blocks for key in block})
    rows = [f"<tr><th>{html.escape(key)}</th>{''.join(_cell(block.get(key)) for block in blocks)}</tr>" for key in keys]
    return f"<table>{_header(runs, 'stage')}{''.join(rows)}</table>"


def _config_table(runs: Sequence[RunFolder]) -> str:
    """The settings that differ between the runs; one run: those that differ from the defaults."""
    if len(runs) == 1:  # the defaults as a results folder's config.yaml holds them
        columns = [flatten(load_yaml(dump_config(NeoSLAMConfig()))), runs[0].config]
        header = f"<tr><th>setting</th><th>default</th><th>{html.escape(runs[0].name)}</th></tr>"
    else:
        columns = [run.config for run in runs]
        header = _header(runs, "setting")
    keys = sorted({key for column in columns for key in column})
    differing = [key for key in keys if len({_canonical(column.get(key)) for column in columns}) > 1]
    if not differing:
        return "<p>No setting differs.</p>"
    rows = [f"<tr><th>{html.escape(k)}</th>{''.join(_cell(c.get(k)) for c in columns)}</tr>" for k in differing]
    return f"<table>{header}{''.join(rows)}</table>"


def _figures(runs: Sequence[RunFolder]) -> str:
    sections = []
    for name, caption in FIGURES.items():
        if not any(name in run.figures for run in runs):
            continue
        cells = []
        for run in runs:
            data = run.figures.get(name)
            if data is None:
                cells.append(f"<td>{ABSENT}</td>")
                continue
            source = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
            alt = html.escape(f"{run.name}: {caption}")
            cells.append(f'<td><figure><img src="{source}" alt="{alt}"></figure></td>')
        sections.append(f'<h3>{html.escape(caption)}</h3><table class="figures"><tr>{"".join(cells)}</tr></table>')
    return "".join(sections) or "<p>No figures: the runs wrote no plots.</p>"


def render_report(runs: Sequence[RunFolder]) -> str:
    """The page of one run or of several side by side (in the order given)."""
    if not runs:
        raise ValueError("a report needs a run")
    title = "NeoSLAM report: " + ", ".join(run.name for run in runs)
    body = [
        f"<h1>{html.escape(title)}</h1>",
        "<h2>Metrics</h2>",
        _metrics_table(runs),
        "<h2>Figures</h2>",
        _figures(runs),
        "<h2>Time by stage</h2>",
        _timing_table(runs),
        "<h2>Configuration that differed</h2>",
        _config_table(runs),
    ]
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title)}</title>\n<style>{STYLE}:root {{ --runs: {len(runs)}; }}\n</style>\n"
        "</head>\n<body>\n" + "\n".join(body) + "\n</body>\n</html>\n"
    )
