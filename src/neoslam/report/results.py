"""What a report reads of a results folder (docs/results.md): metrics.json, config.yaml and the plots. Each problem
is one line naming the file."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from neoslam.errors import InputError
from neoslam.text import read_text, read_yaml

__all__ = ["FIGURES", "RunFolder", "read_results", "flatten"]

# The figures a report shows, in its order, with their captions; a run has those its data allowed.
FIGURES = {
    "map_2d.png": "The map from above: trajectories, loop closures (green true, red false), sessions, objects",
    "detections.png": "What the detector saw at some keyframes: class, score, stereo depth",
    "error_along_route.png": "Position error along the route, aligned as the ATE",
    "precision_recall.png": "Loop closures: precision against recall as the score threshold rises",
    "map_3d.png": "The trajectories in 3-D",
    "keyframe_labels.png": "The keyframes' objects by class",
    "matching_scores.png": "A recognised keyframe's matching scores against the stored ones",
    "ovcn_loss.png": "Training loss of the object-vector cells network",
}
MAX_FIGURE_BYTES = 20 * 2**20  # a plot larger than this is not one `neoslam run` wrote: refused
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class RunFolder:
    """A results folder as a report shows it: its name (the folder's, never its path), metrics, configuration
    (flattened to dotted keys) and figures (file name -> PNG bytes)."""

    name: str
    metrics: dict[str, Any]
    config: dict[str, Any]
    figures: dict[str, bytes]


def flatten(tree: Any, prefix: str = "") -> dict[str, Any]:
    """{"a": {"b": 1}} -> {"a.b": 1}; lists and scalars are values."""
    if not isinstance(tree, dict):
        return {prefix: tree} if prefix else {}
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        flat |= flatten(value, f"{prefix}.{key}" if prefix else str(key))
    return flat


def _metrics(folder: Path) -> dict[str, Any]:
    path = folder / "metrics.json"
    if not path.is_file():
        raise InputError(folder, "not a results folder of `neoslam run`: it has no metrics.json")
    try:
        metrics = json.loads(read_text(path, "metrics.json not found"))
    except json.JSONDecodeError as error:
        raise InputError(path, f"not valid JSON ({error.msg})", line=error.lineno) from None
    if not isinstance(metrics, dict) or not isinstance(metrics.get("frames"), int):
        raise InputError(path, "not the metrics of a run: no whole number of frames")
    return metrics


def _config(folder: Path) -> dict[str, Any]:
    path = folder / "config.yaml"
    if not path.is_file():
        return {}
    tree = read_yaml(path, "config.yaml not found")
    if tree is not None and not isinstance(tree, dict):
        raise InputError(path, "not a configuration: a mapping of sections is expected")
    return flatten(tree or {})


def _figures(folder: Path) -> dict[str, bytes]:
    figures = {}
    for name in FIGURES:
        path = folder / "plots" / name
        if not path.is_file():
            continue
        if path.stat().st_size > MAX_FIGURE_BYTES:
            raise InputError(path, f"larger than {MAX_FIGURE_BYTES // 2**20} MiB: not a plot of `neoslam run`")
        data = path.read_bytes()
        if not data.startswith(PNG_SIGNATURE):
            raise InputError(path, "not a PNG image")
        figures[name] = data
    return figures


def read_results(folder: Path) -> RunFolder:
    """A results folder of `neoslam run` (or the live node), for a report."""
    if not folder.is_dir():
        raise InputError(folder, "not found" if not folder.exists() else "not a folder")
    return RunFolder(folder.resolve().name, _metrics(folder), _config(folder), _figures(folder))
