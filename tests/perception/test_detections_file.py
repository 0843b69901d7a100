"""Detections file (JSON lines): round trip, lookup, class filter, clipping and one precise error per fault."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from neoslam.errors import InputError
from neoslam.perception.detection import Detection
from neoslam.perception.detections_file import DetectionsFile, write_detections_file

CLASSES = ["car", "truck", "bicycle", "person"]
HUGE = "9" * 400  # an integer literal beyond any float
GOOD = {"label": "car", "score": 0.9, "box": [10.0, 20.0, 110.0, 80.0]}


def _write(tmp_path: Path, *lines: str) -> Path:
    path = tmp_path / "detections.jsonl"
    path.write_text("".join(line + "\n" for line in lines), encoding="utf-8")
    return path


def _line(frame: object = 0, **detection: object) -> str:
    return json.dumps({"frame": frame, "detections": [{**GOOD, **detection}]})


def test_round_trip(tmp_path: Path) -> None:
    per_frame = {
        3: [Detection("car", 0.123456789, [1.5, 2.25, 30.125, 40.0]), Detection("person", 1.0, [0, 0, 5, 20])],
        0: [],
        1: [Detection("truck", 0.0, [100, 100, 200, 150])],
    }
    path = tmp_path / "out.jsonl"
    write_detections_file(path, per_frame)
    assert [json.loads(line)["frame"] for line in path.read_text().splitlines()] == [0, 1, 3]
    source = DetectionsFile(path, CLASSES)
    assert source.frames == (0, 1, 3)
    for frame, detections in per_frame.items():
        assert source.detect(frame, None) == detections


def test_absent_frames_have_no_detections(tmp_path: Path) -> None:
    source = DetectionsFile(_write(tmp_path, _line(frame=5)), CLASSES)
    assert source.detect(4, np.zeros((375, 1242), dtype=np.uint8)) == []
    assert len(source.detect(5, np.zeros((375, 1242), dtype=np.uint8))) == 1


def test_labels_outside_the_classes_are_dropped(tmp_path: Path) -> None:
    line = json.dumps({"frame": 0, "detections": [GOOD, {**GOOD, "label": "traffic light"}]})
    assert [d.label for d in DetectionsFile(_write(tmp_path, line), CLASSES).detect(0, None)] == ["car"]
    assert DetectionsFile(_write(tmp_path, line), ["person"]).detect(0, None) == []


def test_boxes_are_clipped_to_the_image(tmp_path: Path) -> None:
    inside_out = json.dumps(
        {"frame": 0, "detections": [{**GOOD, "box": [-5, 10, 50, 400]}, {**GOOD, "box": [2000, 10, 2100, 50]}]}
    )
    source = DetectionsFile(_write(tmp_path, inside_out), CLASSES)
    (clipped,) = source.detect(0, np.zeros((375, 1242, 3), dtype=np.uint8))
    np.testing.assert_array_equal(clipped.box, [0, 10, 50, 375])
    assert len(source.detect(0, None)) == 2  # no image: as in the file


def test_empty_file_and_blank_lines_are_allowed(tmp_path: Path) -> None:
    assert DetectionsFile(_write(tmp_path), CLASSES).frames == ()
    source = DetectionsFile(_write(tmp_path, "", _line(frame=2), "   "), CLASSES)
    assert source.frames == (2,)


def test_extra_keys_are_ignored(tmp_path: Path) -> None:
    line = json.dumps({"frame": 0, "time": 0.1, "detections": [{**GOOD, "track_id": 7}]})
    assert len(DetectionsFile(_write(tmp_path, line), CLASSES).detect(0, None)) == 1


@pytest.mark.parametrize(
    ("line", "problem"),
    [
        ("{not json", "not JSON"),
        ("[1, 2]", "JSON object"),
        (json.dumps({"detections": []}), 'missing key "frame"'),
        (json.dumps({"frame": 0}), 'missing key "detections"'),
        (json.dumps({"frame": 0, "detections": {}}), '"detections" must be a list'),
        (_line(frame=-1), "non-negative integer"),
        (_line(frame=1.5), "non-negative integer"),
        (_line(frame=True), "non-negative integer"),
        (json.dumps({"frame": 0, "detections": [1]}), "detection 0: must be an object"),
        (json.dumps({"frame": 0, "detections": [{"score": 0.5, "box": [0, 0, 1, 1]}]}), 'missing key "label"'),
        (json.dumps({"frame": 0, "detections": [{"label": "car", "box": [0, 0, 1, 1]}]}), 'missing key "score"'),
        (json.dumps({"frame": 0, "detections": [{"label": "car", "score": 0.5}]}), 'missing key "box"'),
        (_line(label=""), "non-empty string"),
        (_line(label=3), "non-empty string"),
        (_line(score=1.5), "in \\[0, 1\\]"),
        (_line(score=-0.1), "in \\[0, 1\\]"),
        (_line(score="0.5"), "in \\[0, 1\\]"),
        ('{"frame": 0, "detections": [{"label": "car", "score": NaN, "box": [0, 0, 1, 1]}]}', "score"),
        ('{"frame": 0, "detections": [{"label": "car", "score": 0.5, "box": [0, 0, Infinity, 1]}]}', "4 finite"),
        ('{"frame": 0, "detections": [{"label": "car", "score": 0.5, "box": [NaN, 0, 1, 1]}]}', "4 finite"),
        # Integer literals beyond any float: JSON reads them as Python ints, which overflow on conversion.
        ('{"frame": 0, "detections": [{"label": "car", "score": ' + HUGE + ', "box": [0, 0, 1, 1]}]}', "score"),
        ('{"frame": 0, "detections": [{"label": "car", "score": 0.5, "box": [0, 0, ' + HUGE + ", 1]}]}", "4 finite"),
        (_line(box=[0, 0, 1]), "4 finite numbers"),
        (_line(box=[0, 0, 1, "2"]), "4 finite numbers"),
        (_line(box="0 0 1 1"), "4 finite numbers"),
        (_line(box=[10, 0, 10, 5]), "x1 < x2"),
        (_line(box=[0, 5, 10, 2]), "y1 < y2"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path: Path, line: str, problem: str) -> None:
    path = _write(tmp_path, _line(frame=0).replace('"frame": 0', '"frame": 9'), "", line)
    with pytest.raises(InputError, match=problem) as raised:
        DetectionsFile(path, CLASSES)
    assert raised.value.path == path and raised.value.line == 3
    assert str(raised.value).startswith(f"{path}:3: ")
    assert "\n" not in str(raised.value)


def test_duplicate_frame(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="frame 4 appears twice") as raised:
        DetectionsFile(_write(tmp_path, _line(frame=4), _line(frame=1), _line(frame=4)), CLASSES)
    assert raised.value.line == 3


def test_missing_and_undecodable_files(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="detections file not found") as raised:
        DetectionsFile(tmp_path / "absent.jsonl", CLASSES)
    assert raised.value.path == tmp_path / "absent.jsonl"
    binary = tmp_path / "binary.jsonl"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(InputError, match=r"not a text file \(not UTF-8: byte 0xff\)"):  # as every text reader says
        DetectionsFile(binary, CLASSES)


def test_writer_refuses_what_the_reader_would(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="non-negative"):
        write_detections_file(tmp_path / "a.jsonl", {-1: []})
    with pytest.raises(ValueError):
        write_detections_file(tmp_path / "b.jsonl", {0: [Detection("car", float("nan"), [0, 0, 1, 1])]})
    with pytest.raises(ValueError, match="x1 < x2"):
        write_detections_file(tmp_path / "c.jsonl", {0: [Detection("car", 0.5, [5, 0, 1, 1])]})
    assert not any(tmp_path.iterdir())
