"""The front end's speed on real frames at the same recall: the detector's windows by recall and cost, and the whole
system on kitti_06_51 with the previous settings and today's default interleaved in one run.

(a) windows: each candidate set of detector windows over the hand-labelled frames (`tests/data/labels/`: frames 0,
    5, ..., 50 of kitti_06_51 and the KITTI object pair): vehicle recall by distance band, nearer than 40 m and over
    all, false detections a frame, the network's input pixels and the median ms of a frame's detection. A row
    "keeps" the reference when its recall is not lower in any band, nearer than 40 m or overall, and its false
    detections are not more; the cheapest such row is named.
(b) speed: the whole system (read, detection, stereo, odometry, NeoSLAM's step) over kitti_06_51's 51 frames, each
    configuration in a fresh process, the configurations interleaved round after round so that the machine's
    load falls on all alike: per-stage median and 95th-percentile ms, frames a second (the wall time of frames 2 to
    51, the first carrying the network's warm-up), the process's peak memory, and what it made (objects placed a
    frame, keyframes, mapped objects, the stereo odometry's distance and heading error over the 51 frames, and a
    digest of the frames that shows which configurations give the same bytes).
(c) revisit: kitti_06_51 forward, back and forward again through a photometric change (`real_streets`' revisit):
    the odometry's end-point error over the 151 frames and the loops closed, for each configuration.

The reference ("previous") is the front end as it was before its speed work: one frame at a time, the road band
enlarged 1.5x, contrast equalised through LAB, a 13 px Lucas-Kanade window and ORB pyramid scale 1.2.

    python -m benchmarks.frontend_speed [--quick] [--parts windows speed revisit] [--rounds 5]

Speed figures of a loaded machine are worth little: the stamp records the load average; compare the ratios.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import hashlib
import math
import multiprocessing
import resource
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks._perception import MIN_IOU, SEQUENCE, _labelled_images
from benchmarks.harness import data_root
from benchmarks.real_streets import THIRD_PASS, TRUE_CLOSURE_M
from neoslam.config import NeoSLAMConfig
from neoslam.config.perception import DetectionPass, DetectorConfig
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.replay import forward_back_forward
from neoslam.evaluation.detection import detection_stats, match_frame
from neoslam.geometry import invert_pose, yaw_of
from neoslam.perception.detection import Detection, ObjectDetector, network_size, to_bgr
from neoslam.perception.detector import make_detector, windows_of
from neoslam.perception.frontend import STAGES, ImageDataset, open_front_end
from neoslam.pipeline import run
from neoslam.types import Frame, Trajectory

QUICK = "2 rounds of (b) instead of 5, and (a) with the reference and the default only"
PARTS = ["windows", "speed", "revisit"]
ROUNDS, QUICK_ROUNDS = 5, 2
REPEATS = 3  # detections of each labelled frame timed in (a)

HALF = DetectionPass(scale=0.5)
KITTI_SIZE = (1226, 370)  # a KITTI odometry frame (sequences 04-12), px


def band(scale: float, rows: tuple[float, float] = (0.32, 0.78), columns: tuple[float, float] = (0.0, 1.0)):
    """The road band: the rows that hold KITTI's road and parked cars, enlarged for the distant ones."""
    return DetectionPass(rows=rows, columns=columns, scale=scale)


WINDOWS: dict[str, list[DetectionPass]] = {
    "frame x0.5": [HALF],
    "frame x0.75": [DetectionPass(scale=0.75)],
    "road band x1.5": [band(1.5)],
    "frame x0.5 + band x1.0": [HALF, band(1.0)],
    "frame x0.5 + band x1.25": [HALF, band(1.25)],
    "frame x0.5 + band x1.5": [HALF, band(1.5)],
    "frame x0.4 + band x1.25": [DetectionPass(scale=0.4), band(1.25)],
    "frame x0.4 + band x1.5": [DetectionPass(scale=0.4), band(1.5)],
    "frame x0.5 + band rows 0.34-0.70 x1.25": [HALF, band(1.25, rows=(0.34, 0.70))],
    "frame x0.5 + band rows 0.34-0.70 x1.5": [HALF, band(1.5, rows=(0.34, 0.70))],
    "frame x0.5 + band columns 0.1-0.9 x1.5": [HALF, band(1.5, columns=(0.1, 0.9))],
    "frame x0.5 + band x1.75": [HALF, band(1.75)],
}


def previous_config() -> NeoSLAMConfig:
    """The front end before its speed work (the LAB contrast path is the detector wrapper `ThroughLab`)."""
    base = NeoSLAMConfig()
    perception = base.perception
    detector = perception.detector.model_copy(update={"passes": [HALF, band(1.5)]})
    odometry = perception.odometry.model_copy(update={"klt_window": 13})
    stereo = perception.stereo.model_copy(update={"orb_scale_factor": 1.2})
    changes = {"detector": detector, "odometry": odometry, "stereo": stereo, "pipeline_depth": 0}
    return base.model_copy(update={"perception": perception.model_copy(update=changes)})


class ThroughLab:
    """A detector given BGR images: its contrast equalisation goes through LAB's lightness, as it did for grey
    frames before they were equalised as they are."""

    def __init__(self, detector: ObjectDetector) -> None:
        self.detector = detector

    def detect(self, frame_index: int, image: np.ndarray) -> list[Detection]:
        return self.detector.detect(frame_index, to_bgr(image))


def with_changes(base: NeoSLAMConfig, **perception_changes) -> NeoSLAMConfig:
    return base.model_copy(update={"perception": base.perception.model_copy(update=perception_changes)})


CONFIGURATIONS = {
    "previous": lambda: previous_config(),
    "default, one frame at a time": lambda: with_changes(NeoSLAMConfig(), pipeline_depth=0),
    "default": lambda: NeoSLAMConfig(),
}


def open_configuration(name: str, sequence) -> tuple[NeoSLAMConfig, ImageDataset]:
    config = CONFIGURATIONS[name]()
    dataset = open_front_end(sequence, config.perception)
    if name == "previous":
        dataset.front_end.detector = ThroughLab(dataset.front_end.detector)
    return config, dataset


# --- (a) the windows' recall and cost --------------------------------------------------------------------------


def _input_pixels(detector: DetectorConfig, image_size: tuple[int, int]) -> int:
    """The network's input pixels over the windows of one image of that size."""
    windows = windows_of(detector, image_size)
    return sum(math.prod(network_size(w.x1 - w.x0, w.y1 - w.y0, w.scale)) for w in windows)


def _window_row(name: str, detector: ObjectDetector, config: DetectorConfig, images: list) -> dict:
    detector.detect(0, images[0][0])  # warm-up
    matches, times = [], []
    for repeat in range(REPEATS):
        for image, labels in images:
            start = time.perf_counter()
            detections = detector.detect(0, image)
            times.append(time.perf_counter() - start)
            if repeat == 0:
                boxes = np.array([d.box for d in detections]).reshape(-1, 4)
                matches.append(match_frame(labels, boxes, [d.label for d in detections], MIN_IOU))
    stats = detection_stats(matches)
    row = {"windows": name, "network px (KITTI frame)": _input_pixels(config, KITTI_SIZE)}
    row |= stats.as_row() | {"ms / frame": float(np.median(times) * 1e3), "_stats": stats}
    return row


def _keeps_recall(row: dict, reference: dict) -> bool:
    """Recall not lower in any band, nearer than 40 m or overall; false detections not more."""
    stats, ref = row["_stats"], reference["_stats"]
    bands = all(stats.by_band[b][0] >= ref.by_band[b][0] for b in ref.by_band)
    return (
        bands
        and stats.found >= ref.found
        and stats.recall_nearer_40m >= ref.recall_nearer_40m
        and stats.false_positives_per_frame <= ref.false_positives_per_frame
    )


def _keeps_map(row: dict, reference: dict) -> bool:
    """Keeps the recall, and makes as many keyframes and mapped objects on kitti_06_51."""
    if row["keeps the recall"] != "yes":
        return False
    return all(m >= p for m, p in zip(row["_made"], reference["_made"], strict=True))


def _note_made(row: dict, made: tuple[int, int]) -> None:
    row["_made"] = made
    row["keyframes, mapped objects"] = f"{made[0]}, {made[1]}"


def _mapped_on_the_street(config: NeoSLAMConfig, through_lab: bool = False) -> tuple[int, int]:
    """Keyframes and mapped objects of the whole system on kitti_06_51 with this configuration."""
    dataset = open_front_end(read_kitti_sequence(data_root() / "kitti_06_51", SEQUENCE), config.perception)
    if through_lab:
        dataset.front_end.detector = ThroughLab(dataset.front_end.detector)
    result = run(dataset.frames(), config, total=len(dataset), progress=False)
    return len(result.keyframes), len(result.objects)


def run_windows(bench: harness.Run, args: argparse.Namespace) -> dict:
    images = _labelled_images()
    default = NeoSLAMConfig().perception.detector
    previous = previous_config().perception.detector
    reference = _window_row(
        "previous: frame x0.5 + band x1.5, LAB contrast",
        ThroughLab(make_detector(previous)),
        previous,
        images,
    )
    candidates = {"default": list(default.passes)} if args.quick else WINDOWS
    rows = [reference]
    for name, passes in candidates.items():
        config = default.model_copy(update={"passes": passes})
        rows.append(_window_row(name, make_detector(config), config, images))
    _note_made(reference, _mapped_on_the_street(previous_config(), through_lab=True))
    for row, passes in zip(rows[1:], candidates.values(), strict=True):
        row["keeps the recall"] = "yes" if _keeps_recall(row, reference) else "no"
        if row["keeps the recall"] == "yes":  # the whole system only where the detector alone keeps up
            detector = default.model_copy(update={"passes": passes})
            config = with_changes(NeoSLAMConfig(), detector=detector)
            _note_made(row, _mapped_on_the_street(config))
        row["keeps both"] = "yes" if _keeps_map(row, reference) else "no"
    kept = [r for r in rows[1:] if r["keeps both"] == "yes"]
    cheapest = min(kept, key=lambda r: r["ms / frame"])["windows"] if kept else None
    columns = ["windows", "network px (KITTI frame)", "ms / frame", "recall < 40 m", "recall", "FP / frame"]
    columns += [c for c in rows[0] if c.startswith("found ")]
    columns += ["keeps the recall", "keyframes, mapped objects", "keeps both"]
    bench.table(
        "windows",
        rows,
        columns,
        title=f"## (a) The detector's windows (grey contrast equalisation); the cheapest that keeps both: {cheapest}",
    )
    kept_rows = [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]
    return {"windows": kept_rows, "cheapest_keeping": cheapest}


def _odometry_errors(estimate: np.ndarray, truth: Trajectory) -> tuple[float, float]:
    """Distance travelled (relative error, %) and heading change (error, degrees) over the sequence."""
    travelled = np.linalg.norm(np.diff(estimate[:, :3, 3], axis=0), axis=1).sum()
    distance_error = 100.0 * (travelled / truth.path_length() - 1.0)
    turn = yaw_of(estimate[-1:])[0] - yaw_of(estimate[:1])[0]
    true_turn = yaw_of(truth.poses[-1:])[0] - yaw_of(truth.poses[:1])[0]
    return float(distance_error), float(np.degrees(abs(turn - true_turn)))


# --- (b) the whole system's speed ------------------------------------------------------------------------------


def _frames_digest(frames: list[Frame]) -> str:
    """A short digest of what the front end gave: each frame's pose and objects (label, score, boxes, centre)."""
    digest = hashlib.sha256()
    for frame in frames:
        digest.update(np.ascontiguousarray(frame.odometry_pose).tobytes())
        for o in frame.observations:
            digest.update(f"{o.label} {o.score!r}".encode())
            for array in (o.box_left, o.box_right, o.center_camera, o.patch):
                digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()[:12]


def _passed_on(frames: Iterator[Frame], seen: list[Frame], marks: list[float]) -> Iterator[Frame]:
    """The frames as they come, each kept with the time it reached the back end."""
    for frame in frames:
        marks.append(time.perf_counter())
        seen.append(frame)
        yield frame


def measure_once(name: str, replay: bool = False) -> dict:
    """One run of the configuration over kitti_06_51 (or its replayed revisit) in this process."""
    sequence = read_kitti_sequence(data_root() / "kitti_06_51", SEQUENCE)
    if replay:
        sequence = forward_back_forward(sequence, THIRD_PASS)
    config, dataset = open_configuration(name, sequence)
    frames: list[Frame] = []
    marks: list[float] = []
    result = run(_passed_on(dataset.frames(), frames, marks), config, total=len(sequence), progress=False)
    wall_s = time.perf_counter() - marks[1]  # from the second frame: the first carries the network's warm-up
    truth = sequence.ground_truth
    poses = np.array([f.odometry_pose for f in frames])
    distance_error, heading_error = _odometry_errors(poses, truth)
    end_error = float(np.linalg.norm(poses[-1, :3, 3] - (invert_pose(truth.poses[0]) @ truth.poses[-1])[:3, 3]))
    gaps = [
        np.linalg.norm(truth.poses[c.query_frame, :3, 3] - truth.poses[c.match_frame, :3, 3])
        for c in result.loop_closures
    ]
    return {
        "configuration": name,
        "stages": {s: list(dataset.front_end.times.stages[s]) for s in STAGES}
        | {"back end": list(result.frame_times_s)},
        "fps": (len(frames) - 1) / wall_s,
        "peak memory MB": _peak_memory_mb(),
        "placed / frame": float(np.mean([len(f.observations) for f in frames])),
        "keyframes": len(result.keyframes),
        "mapped objects": len(result.objects),
        "odometry distance error %": distance_error,
        "odometry heading error deg": heading_error,
        "odometry end error % of path": 100.0 * end_error / truth.path_length(),
        "closures": len(result.loop_closures),
        "false closures": int(sum(g > TRUE_CLOSURE_M for g in gaps)),
        "keyframes made (pass 1 / 3)": _keyframes_by_pass(result.keyframe_frames, len(frames)),
        "frames digest": _frames_digest(frames),
    }


def _keyframes_by_pass(keyframe_frames: np.ndarray, frames: int) -> str:
    """Keyframes made (stored, or recognised as stored ones) in the first and the third pass of the revisit."""
    made = np.asarray(keyframe_frames, dtype=int)
    length = (frames + 2) // 3  # forward, back, forward again: 3 n - 2 frames
    return f"{int(np.sum(made < length))} / {int(np.sum(made >= 2 * length - 1))}"


def _peak_memory_mb() -> float:
    """This process's peak resident memory. Linux's VmHWM belongs to the process image, while getrusage's maxrss
    carries over the parent's peak into a child it forks and execs."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _in_fresh_process(name: str, replay: bool = False) -> dict:
    """`measure_once` in a process of its own: its peak memory is the configuration's alone."""
    context = multiprocessing.get_context("spawn")
    with concurrent.futures.ProcessPoolExecutor(1, mp_context=context) as executor:
        return executor.submit(measure_once, name, replay).result()


STAGE_NAMES = [*STAGES, "back end"]
MADE = ["placed / frame", "keyframes", "mapped objects", "odometry distance error %", "odometry heading error deg"]


def _speed_row(name: str, runs: list[dict]) -> dict:
    """Stage times pooled over the runs (median, p95), frames a second and peak memory as the runs' medians."""
    row: dict = {"configuration": name, "runs": len(runs)}
    for stage in STAGE_NAMES:
        times = np.concatenate([r["stages"][stage] for r in runs]) * 1e3
        row[f"{stage} ms"] = f"{np.median(times):.1f} / {np.percentile(times, 95):.1f}"
        row[f"_{stage}"] = float(np.median(times))
    row["fps"] = float(np.median([r["fps"] for r in runs]))
    row["peak memory MB"] = float(np.median([r["peak memory MB"] for r in runs]))
    last = runs[-1]
    row |= {key: last[key] for key in [*MADE, "frames digest"]}
    return row


def run_speed(bench: harness.Run, args: argparse.Namespace) -> dict:
    rounds = QUICK_ROUNDS if args.quick else args.rounds
    runs: dict[str, list[dict]] = {name: [] for name in CONFIGURATIONS}
    for _ in range(rounds):
        for name in CONFIGURATIONS:  # interleaved: a change of the machine's load falls on every configuration
            runs[name].append(_in_fresh_process(name))
    rows = [_speed_row(name, r) for name, r in runs.items()]
    reference = rows[0]["fps"]
    for row in rows:
        row["fps / previous"] = row["fps"] / reference
    columns = ["configuration", "runs", *(f"{s} ms" for s in STAGE_NAMES), "fps", "fps / previous"]
    columns += ["peak memory MB", *MADE, "frames digest"]
    bench.table(
        "speed",
        rows,
        columns,
        title="## (b) The whole system on kitti_06_51 (stage ms: median / 95th percentile)",
    )
    return {"speed": [{k: v for k, v in r.items() if not k.startswith("_")} for r in rows]}


def run_revisit(bench: harness.Run, args: argparse.Namespace) -> dict:
    names = ["previous", "default"]
    rows = [_in_fresh_process(name, replay=True) for name in names]
    columns = ["configuration", "odometry end error % of path", "odometry heading error deg", "keyframes"]
    columns += ["keyframes made (pass 1 / 3)"]
    columns += ["closures", "false closures", "frames digest"]
    bench.table("revisit", rows, columns, title="## (c) The revisit: forward, back, forward again (151 frames)")
    return {"revisit": [{c: r[c] for c in columns} for r in rows]}


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=PARTS, help="which parts to run (default all)")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help=f"rounds of (b) (default {ROUNDS})")


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    figures: dict = {}
    if "windows" in bench.args.parts:
        figures |= run_windows(bench, bench.args)
    if "speed" in bench.args.parts:
        figures |= run_speed(bench, bench.args)
    if "revisit" in bench.args.parts:
        figures |= run_revisit(bench, bench.args)
    bench.finish(figures)


if __name__ == "__main__":
    main()
