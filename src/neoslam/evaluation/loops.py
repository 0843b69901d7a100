"""Ground-truth judgement of loop closures: which frames truly revisit a place, which closures are right, and
precision / recall (also swept over the closures' scores). Pure maths on ground-truth positions.

A closure (query q, match m) is true when m is at least `min_frame_gap` frames before q (q - m >= gap) and the
ground-truth positions are at most `max_distance_m` apart. A frame i truly revisits a place when some frame
j <= i - gap lies within `max_distance_m`.

Undefined ratios are NaN, never a flattering number: precision with nothing accepted, recall (and the swept
figures) when no query frame has a true revisit, F1 when precision or recall is undefined.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.spatial import cKDTree

from neoslam.types import LoopClosure

__all__ = [
    "LoopCriteria",
    "DEFAULT_CRITERIA",
    "LoopStats",
    "PrecisionRecall",
    "true_revisits",
    "judge_closures",
    "evaluate_closures",
    "precision_recall_curve",
]

ClosureLike = LoopClosure | tuple[int, int, float]


@dataclass(frozen=True, slots=True)
class LoopCriteria:
    max_distance_m: float = 5.0
    min_frame_gap: int = 100


DEFAULT_CRITERIA = LoopCriteria()


@dataclass(frozen=True, slots=True)
class LoopStats:
    accepted: int
    true_positive: int
    false_positive: int
    revisit_frames: int  # query frames with a true revisit (the recall denominator)
    recalled_frames: int  # distinct query frames with at least one true closure
    precision: float
    recall: float
    f1: float
    recall_at_full_precision: float  # best recall of any score threshold whose closures are all true
    f1_max: float  # best F1 over the score thresholds

    def as_dict(self) -> dict[str, int | float | None]:
        """JSON-friendly values: NaN becomes None."""
        return {
            key: None if isinstance(value, float) and math.isnan(value) else value
            for key, value in asdict(self).items()
        }


def _query_indices(n_frames: int, query_frames: Sequence[int] | np.ndarray | None) -> np.ndarray:
    if query_frames is None:
        return np.arange(n_frames)
    frames = np.asarray(query_frames, dtype=int)
    if frames.size and (frames.min() < 0 or frames.max() >= n_frames):
        raise ValueError(f"query frames must lie in [0, {n_frames}), got [{frames.min()}, {frames.max()}]")
    return frames


def true_revisits(
    gt_positions: np.ndarray,
    criteria: LoopCriteria = DEFAULT_CRITERIA,
    query_frames: Sequence[int] | np.ndarray | None = None,
) -> np.ndarray:
    """Bool per query frame (all frames by default): some frame j <= i - gap lies within max_distance_m."""
    positions = np.asarray(gt_positions, dtype=float)
    frames = _query_indices(len(positions), query_frames)
    tree = cKDTree(positions)
    neighbours = tree.query_ball_point(positions[frames], r=criteria.max_distance_m, return_sorted=False)
    latest_allowed = frames - criteria.min_frame_gap
    return np.array(
        [len(near) > 0 and min(near) <= last for near, last in zip(neighbours, latest_allowed, strict=True)],
        dtype=bool,
    )


def _closure_arrays(closures: Iterable[ClosureLike]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rows = [(c.query_frame, c.match_frame, c.score) if isinstance(c, LoopClosure) else tuple(c) for c in closures]
    if not rows:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0)
    query, match, score = zip(*rows, strict=True)
    return np.asarray(query, dtype=int), np.asarray(match, dtype=int), np.asarray(score, dtype=float)


def judge_closures(
    closures: Iterable[ClosureLike],
    gt_positions: np.ndarray,
    criteria: LoopCriteria = DEFAULT_CRITERIA,
) -> np.ndarray:
    """Bool per closure: true when the match is gap frames earlier and within max_distance_m of the query."""
    query, match, _ = _closure_arrays(closures)
    positions = np.asarray(gt_positions, dtype=float)
    distance = np.linalg.norm(positions[query] - positions[match], axis=-1)
    return (query - match >= criteria.min_frame_gap) & (distance <= criteria.max_distance_m)


def _ratio(numerator: float, denominator: float) -> float:
    return numerator / denominator if denominator > 0 else float("nan")


def _f1(precision: np.ndarray | float, recall: np.ndarray | float) -> np.ndarray:
    precision, recall = np.asarray(precision, dtype=float), np.asarray(recall, dtype=float)
    total = precision + recall
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, 2 * precision * recall / total, np.where(np.isnan(total), np.nan, 0.0))


def _count_at_least(values: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """For each threshold t, how many values are >= t."""
    return np.searchsorted(np.sort(-values), -thresholds, side="right")


@dataclass(frozen=True)
class PrecisionRecall:
    """Precision and recall of accepting the closures scored at least each threshold (the closures' own scores,
    increasing): the curve a score threshold moves along."""

    thresholds: np.ndarray
    precision: np.ndarray
    recall: np.ndarray


def _curve(scores: np.ndarray, correct: np.ndarray, best_true_score: np.ndarray, n_revisits: int) -> PrecisionRecall:
    thresholds = np.unique(scores)
    accepted = _count_at_least(scores, thresholds)
    true_positive = _count_at_least(scores[correct], thresholds)
    recalled = _count_at_least(best_true_score, thresholds)
    return PrecisionRecall(thresholds, true_positive / np.maximum(accepted, 1), recalled / max(n_revisits, 1))


def _sweep(
    scores: np.ndarray, correct: np.ndarray, best_true_score: np.ndarray, n_revisits: int
) -> tuple[float, float]:
    """(recall at 100 % precision, max F1) over the thresholds 'accept closures with score >= t', t = each score.

    Recall at full precision is 0.0 when no threshold gives 100 % precision (or there are no closures).
    """
    if n_revisits == 0:
        return float("nan"), float("nan")
    if scores.size == 0:
        return 0.0, 0.0
    curve = _curve(scores, correct, best_true_score, n_revisits)
    full_precision = curve.precision == 1.0
    recall_full = float(curve.recall[full_precision].max()) if full_precision.any() else 0.0
    return recall_full, float(np.nanmax(_f1(curve.precision, curve.recall)))


def _best_true_score_per_frame(query: np.ndarray, score: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Highest score of a true closure for each distinct counted query frame that has one."""
    best: dict[int, float] = {}
    for frame, value in zip(query[counts], score[counts], strict=True):
        best[int(frame)] = max(value, best.get(int(frame), -np.inf))
    return np.array(list(best.values()), dtype=float)


def _judged(
    closures: list[ClosureLike],
    gt_positions: np.ndarray,
    criteria: LoopCriteria,
    query_frames: Sequence[int] | np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Each closure's score and verdict, the best true score of each recalled query frame, and the revisits."""
    query, _, score = _closure_arrays(closures)
    correct = judge_closures(closures, gt_positions, criteria)
    frames = _query_indices(len(gt_positions), query_frames)
    revisit = frames[true_revisits(gt_positions, criteria, frames)]
    best_true_score = _best_true_score_per_frame(query, score, correct & np.isin(query, revisit))
    return score, correct, best_true_score, len(revisit)


def precision_recall_curve(
    closures: Iterable[ClosureLike],
    gt_positions: np.ndarray,
    criteria: LoopCriteria = DEFAULT_CRITERIA,
    query_frames: Sequence[int] | np.ndarray | None = None,
) -> PrecisionRecall:
    """The precision-recall curve of the closures' score (recall as in `evaluate_closures`)."""
    return _curve(*_judged(list(closures), gt_positions, criteria, query_frames))


def evaluate_closures(
    closures: Iterable[ClosureLike],
    gt_positions: np.ndarray,
    criteria: LoopCriteria = DEFAULT_CRITERIA,
    query_frames: Sequence[int] | np.ndarray | None = None,
) -> LoopStats:
    """Precision over accepted closures; recall over the query frames (default: all) that truly revisit a place.

    Recall counts distinct query frames: several true closures of one frame recall it once. Closures whose query
    frame is not among `query_frames` still count for precision but not for recall.
    """
    score, correct, best_true_score, revisits = _judged(list(closures), gt_positions, criteria, query_frames)
    true_positive = int(correct.sum())
    precision = _ratio(true_positive, len(correct))
    recall = _ratio(len(best_true_score), revisits)
    recall_full, f1_max = _sweep(score, correct, best_true_score, revisits)
    return LoopStats(
        accepted=len(correct),
        true_positive=true_positive,
        false_positive=len(correct) - true_positive,
        revisit_frames=revisits,
        recalled_frames=len(best_true_score),
        precision=precision,
        recall=recall,
        f1=float(_f1(precision, recall)),
        recall_at_full_precision=recall_full,
        f1_max=f1_max,
    )
