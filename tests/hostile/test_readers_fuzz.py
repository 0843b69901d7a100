"""Every reader of a user's file, fed any bytes: a result, or one NeoSLAM error (which the CLI prints as one line
with exit code 2); never another exception, a hang or a write.

Property-based (Hypothesis, derandomised so that CI sees the same cases every run): raw bytes, and text close to
each format (its own alphabet of digits, signs, separators and the words it uses), which reaches further into the
parsers than random bytes do.
"""

from __future__ import annotations

import contextlib
import hashlib
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from neoslam.config import NeoSLAMConfig, load_config
from neoslam.errors import NeoSLAMError

FUZZ = settings(
    max_examples=300, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)

NUMBERS = st.text(alphabet="0123456789.-+eE ,\t\n#naif", max_size=400)
CSV_TEXT = st.text(alphabet='0123456789.-+e,\n\r" cartuk', max_size=400)
JSON_TEXT = st.text(alphabet='{}[]":, 0123456789.-eframdtcionslbxr\n', max_size=400)
YAML_TEXT = st.text(alphabet="abcdefghijklmnopqrstuvwxyz_:-[]{}, 0123456789.\n&*!|>'\"#", max_size=300)
ANY_BYTES = st.binary(max_size=600)


def _reads(reader: Callable[[Path], Any], data: bytes, name: str) -> None:
    """Write `data` to a fresh file, read it: NeoSLAMError or a result; the file is left as it was."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / name
        path.write_bytes(data)
        digest = hashlib.sha256(data).hexdigest()
        with contextlib.suppress(NeoSLAMError):
            reader(path)
        assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
        assert sorted(p.name for p in Path(folder).iterdir()) == [name]


def _text_and_bytes(text_strategy: st.SearchStrategy[str]) -> st.SearchStrategy[bytes]:
    return st.one_of(text_strategy.map(lambda text: text.encode("utf-8")), ANY_BYTES)


@FUZZ
@given(_text_and_bytes(NUMBERS), st.sampled_from(["tum", "kitti", "auto"]))
def test_trajectory_files(data: bytes, fmt: str) -> None:
    from neoslam.io.trajectory_files import read_trajectory

    _reads(lambda path: read_trajectory(path, fmt), data, "trajectory.txt")


@FUZZ
@given(_text_and_bytes(NUMBERS))
def test_times_files(data: bytes) -> None:
    from neoslam.io.trajectory_files import read_times

    _reads(read_times, data, "times.txt")


@FUZZ
@given(_text_and_bytes(CSV_TEXT.map(lambda body: "frame,label,x\n" + body)))
def test_csv_tables(data: bytes) -> None:
    from neoslam.io.tables import numeric_column, read_table

    columns = ("frame", "label", "x")

    def read(path: Path) -> None:
        table = read_table(path, columns)
        numeric_column(path, table, columns, "x")

    _reads(read, data, "table.csv")


@FUZZ
@given(_text_and_bytes(CSV_TEXT.map(lambda body: "query_frame,match_frame,query_keyframe," + body)))
def test_loop_closure_files(data: bytes) -> None:
    from neoslam.io.results import read_loop_closures

    _reads(lambda path: read_loop_closures(path, frames=100), data, "loop_closures.csv")


@FUZZ
@given(_text_and_bytes(JSON_TEXT))
def test_detection_files(data: bytes) -> None:
    from neoslam.perception.detections_file import DetectionsFile

    _reads(lambda path: DetectionsFile(path, ["car"], frame_count=50), data, "detections.jsonl")


@FUZZ
@given(_text_and_bytes(YAML_TEXT))
def test_config_files(data: bytes) -> None:
    _reads(lambda path: load_config(path, environ={}), data, "settings.yaml")


@FUZZ
@given(_text_and_bytes(YAML_TEXT))
def test_sweep_specs(data: bytes) -> None:
    from neoslam.sweep import load_spec

    _reads(load_spec, data, "spec.yaml")


@FUZZ
@given(_text_and_bytes(JSON_TEXT))
def test_label_files(data: bytes) -> None:
    from neoslam.evaluation.detection import read_labels

    _reads(read_labels, data, "labels.json")


@FUZZ
@given(ANY_BYTES, st.booleans())
def test_bag_message_headers(raw: bytes, ros1: bool) -> None:
    """A bag's message header read from raw bytes: a stamp, or a MessageError (the bag reader names the message)."""
    from neoslam.datasets.bag_messages import MessageError, header_stamp_ns

    with contextlib.suppress(MessageError):
        header_stamp_ns(raw, ros1)


@FUZZ
@given(ANY_BYTES.map(lambda tail: b"SQLite format 3\x00" + tail) | ANY_BYTES)
def test_map_files(data: bytes) -> None:
    from neoslam.store.map_file import MapFile

    _reads(lambda path: MapFile.open(path, NeoSLAMConfig(), read_only=True).close(), data, "map.db")


@FUZZ
@given(_text_and_bytes(CSV_TEXT.map(lambda body: "frame,timestamp,vx,vy,vz,wx,wy,wz\n" + body)))
def test_simulated_dataset_frames(data: bytes) -> None:
    from neoslam.datasets.simulated import read_dataset

    def read(path: Path) -> None:
        folder = path.parent / "dataset"
        folder.mkdir()
        (folder / "dataset.yaml").write_text("name: fuzz\nframes: 3\n")
        (folder / "frames.csv").write_bytes(path.read_bytes())
        try:
            read_dataset(folder)
        finally:
            for child in folder.iterdir():
                child.unlink()
            folder.rmdir()

    _reads(read, data, "frames.csv")
