"""Detection recall against labels: IoU, greedy matching, what counts, distance bands, the labels reader."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from neoslam.errors import InputError
from neoslam.evaluation.detection import (
    LabelledObject,
    box_iou,
    detection_stats,
    match_frame,
    read_labels,
)

REPO_LABELS = Path(__file__).resolve().parents[1] / "data" / "labels"


def _car(box, distance=10.0, **flags) -> LabelledObject:
    return LabelledObject("car", tuple(float(v) for v in box), distance, **flags)


def test_box_iou_known_values() -> None:
    a = np.array([[0, 0, 10, 10]])
    b = np.array([[0, 0, 10, 10], [5, 0, 15, 10], [20, 20, 30, 30]])
    np.testing.assert_allclose(box_iou(a, b), [[1.0, 50 / 150, 0.0]])
    assert box_iou(np.zeros((0, 4)), b).shape == (0, 3)


def test_matching_is_greedy_one_to_one_by_iou() -> None:
    labels = [_car([0, 0, 20, 20]), _car([100, 0, 120, 20], distance=30.0)]
    boxes = np.array([[1, 0, 21, 20], [0, 1, 20, 21], [300, 0, 320, 20]])
    match = match_frame(labels, boxes, ["car", "truck", "car"], min_iou=0.4)
    # Two boxes on the first car: one finds it, the other is a duplicate (a false positive), as is the far box.
    assert match.found == (True, False) and match.false_positives == 2


def test_vehicles_match_whatever_the_vehicle_class_but_not_people() -> None:
    labels = [LabelledObject("truck", (0, 0, 40, 30), 20.0)]
    assert match_frame(labels, np.array([[0, 0, 40, 30]]), ["car"], 0.4).found == (True,)
    person = match_frame(labels, np.array([[0, 0, 40, 30]]), ["person"], 0.4)
    assert person.found == (False,) and person.false_positives == 1


def test_doubtful_small_and_other_labels_neither_count_nor_make_false_positives() -> None:
    labels = [
        _car([0, 0, 30, 20], doubtful=True),
        _car([50, 0, 80, 10]),  # 10 px high: below 12
        LabelledObject("person", (100, 0, 110, 30), 8.0),
        _car([200, 0, 240, 30]),
    ]
    boxes = np.array([[0, 0, 30, 20], [50, 0, 80, 10], [100, 0, 110, 30]])
    match = match_frame(labels, boxes, ["car", "car", "person"], 0.4)
    assert [obj.box for obj in match.counted] == [(200.0, 0.0, 240.0, 30.0)]
    assert match.found == (False,) and match.false_positives == 0


def test_stats_by_distance_band() -> None:
    labels = [_car([0, 0, 20, 20], 10.0), _car([40, 0, 60, 20], 30.0), _car([80, 0, 100, 20], 50.0)]
    found = match_frame(labels, np.array([[0, 0, 20, 20], [80, 0, 100, 20], [500, 0, 520, 20]]), ["car"] * 3, 0.4)
    stats = detection_stats([found, match_frame([], np.zeros((0, 4)), [], 0.4)])
    assert stats.frames == 2 and stats.vehicles == 3 and stats.found == 2
    assert stats.recall == pytest.approx(2 / 3) and stats.recall_nearer_40m == pytest.approx(0.5)
    assert stats.false_positives_per_frame == 0.5
    assert stats.by_band == {"< 20 m": (1, 1), "20-40 m": (0, 1), ">= 40 m": (1, 1)}
    assert math.isnan(detection_stats([]).recall)


def test_labels_file_round_trip_and_errors(tmp_path: Path) -> None:
    path = tmp_path / "labels.json"
    item = {"label": "car", "box": [1, 2, 30, 40], "occluded": 1, "truncated": False, "distance_m": 12.5}
    path.write_text(json.dumps({"min_box_height_px": 12, "frames": {"5": [item], "0": []}}))
    frames, height = read_labels(path)
    assert [f.frame for f in frames] == [0, 5] and height == 12
    assert frames[1].objects[0] == LabelledObject("car", (1.0, 2.0, 30.0, 40.0), 12.5, occluded=1)
    for bad, problem in [
        ({"frames": {"x": []}}, "frame key"),
        ({"frames": {"0": [dict(item, box=[30, 2, 1, 40])]}}, "x1 < x2"),
        ({"frames": {"0": [dict(item, distance_m=-1)]}}, "distance_m"),
        ({"frames": {"0": [{"label": "car"}]}}, "needs label, box"),
        ([], "not a labels file"),
    ]:
        path.write_text(json.dumps(bad))
        with pytest.raises(InputError, match=problem):
            read_labels(path)


@pytest.mark.parametrize("name", ["kitti_06_51.json", "kitti_object_pair.json"])
def test_the_shipped_labels_read(name: str) -> None:
    frames, height = read_labels(REPO_LABELS / name)
    vehicles = [o for f in frames for o in f.objects if o.label in ("car", "truck")]
    assert height == 12 and len(vehicles) >= 8
