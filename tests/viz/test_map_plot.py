"""The top view of a run's map carries the map: the accepted loop closures as links (judged true or false against
the ground truth by the loops block's criteria), the objects by class in a legend with their counts and their ids
written beside them, the sessions of a kept map by colour and where this session relocalised. The figure is read
back from matplotlib, not from pixels."""

from __future__ import annotations

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from neoslam.config import EvaluationConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.report import closure_verdicts
from neoslam.geometry import SimilarityTransform
from neoslam.types import Trajectory
from neoslam.viz.map_plot import CLOSURE_LABELS, MAX_LABELLED_OBJECTS, MapLayers, map_figure
from neoslam.viz.run_plots import _layers, write_plots


def _legend_texts(figure: Figure) -> list[str]:
    axes = figure.axes[0]
    legends = [a for a in axes.get_children() if type(a).__name__ == "Legend"]
    return [t.get_text() for legend in legends for t in legend.get_texts()]


def test_a_run_with_loops_draws_each_closure_judged_and_the_objects_by_class(block_seed5, block_seed5_run) -> None:
    truth = read_dataset(block_seed5).ground_truth
    result = block_seed5_run
    identity = SimilarityTransform(np.eye(3), np.zeros(3))
    layers = _layers(result, truth, EvaluationConfig(), identity, "fitted")
    figure = map_figure({"ground truth": truth, "corrected": result.estimate}, layers)
    texts = _legend_texts(figure)
    verdicts = closure_verdicts(result.loop_closures, truth, EvaluationConfig())
    assert len(result.loop_closures) > 0 and verdicts.all()  # the block drive closes true loops only
    assert f"{CLOSURE_LABELS[True]} ({len(result.loop_closures)})" in texts
    links = [c for c in figure.axes[0].collections if isinstance(c, LineCollection)]
    assert sum(len(c.get_segments()) for c in links) == len(result.loop_closures)
    for label in {o.label for o in result.objects}:
        assert f"{label} ({sum(o.label == label for o in result.objects)})" in texts
    ids = {t.get_text() for t in figure.axes[0].texts}
    if len(result.objects) <= MAX_LABELLED_OBJECTS:
        assert {str(o.id) for o in result.objects} <= ids
    assert "fitted" in figure.axes[0].get_title()


def test_false_closures_sessions_and_the_relocalisation_are_shown_apart() -> None:
    ring = np.stack([np.cos(np.linspace(0, 6, 40)) * 50, np.sin(np.linspace(0, 6, 40)) * 50], axis=1)
    layers = MapLayers(
        closures=np.array([[[0, 0], [5, 5]], [[10, 0], [10, 30]], [[20, 0], [21, 1]]], dtype=float),
        closure_truth=np.array([True, False, True]),
        experiences=ring,
        sessions=np.repeat([1, 2], 20),
        relocalised=np.array([3.0, 4.0]),
    )
    figure = map_figure({"corrected": _trajectory(ring)}, layers)
    texts = _legend_texts(figure)
    assert f"{CLOSURE_LABELS[True]} (2)" in texts and f"{CLOSURE_LABELS[False]} (1)" in texts
    assert "session 1 experiences" in texts and "session 2 experiences" in texts
    assert "relocalised in the map" in texts


def test_the_plots_folder_of_a_run_is_written(block_seed5, block_seed5_run, tmp_path) -> None:
    truth = read_dataset(block_seed5).ground_truth
    write_plots(tmp_path / "plots", block_seed5_run, truth, 0.5, EvaluationConfig())
    names = {p.name for p in (tmp_path / "plots").iterdir()}
    assert {"map_2d.png", "map_3d.png", "error_along_route.png", "precision_recall.png"} <= names


def _trajectory(points: np.ndarray) -> Trajectory:
    poses = np.repeat(np.eye(4)[None], len(points), axis=0)
    poses[:, :2, 3] = points
    return Trajectory(np.arange(len(points), dtype=float), poses)
