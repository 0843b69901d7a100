"""A map kept over several sessions: relocalisation, routes that never meet, real images, crashes, cost.

Every run is `neoslam run DATA --out R --map FILE --quiet` in its own process, as a user would run it; the map files
are read back with `neoslam.store.map_file.MapFile` and SQLite. Simulated drives: the real KITTI ground truth, `vo`
odometry, the `real` detection profile (`neoslam.config.profiles.simulation_config`), sessions cut from one drive by
`neoslam.sim.session_drives.session_recordings` (one world of objects, each session from the identity with its own
odometry and detection noise). Closures are judged in ground truth: true when the two frames lie within the
evaluation's loop_max_distance (5 m, horizontally). Ground truth is read here for judging only.

1. KITTI 05 in two sessions: A frames 0-1199 (creates the map), B frames 1200-2760 from the identity (extends it).
   B's relocalisation frame, the distance B drove to it from the first frame on a street A mapped (from the ground
   truth, once B has left the end of A's route: the first B frame within loop_max_distance of an A frame, 1292, and
   within 10 m, 1282) (target <= 30 m from 1292), B's closures with A's keyframes judged
   (no false relocalisation), B's ATE in A's frame without alignment (target <= 2.0 m; A starts at the identity as
   05's ground truth does), with SE(3) alignment for reference, and A's ATE. An unaligned ATE also counts the map
   frame's own error (A's drift from its start), so beside it: the same figures of one uninterrupted run of the
   whole drive (same world, A's noise seed) at the same frames, and of the map as B left it (A's experiences, which
   B's closures corrected too, with B's trajectory) under one alignment for both sessions.
2. Routes that never meet: B = KITTI 08 frames 0-1199 (its own world and noise) run into a copy of A's map: no
   relocalisation, and A's keyframes, experiences and corrected poses unchanged in the map.
3. Real images: A = kitti_06_51 (51 frames of KITTI 06) through the real front end; B = the same frames played back
   then forward (50 ... 0 ... 50) through the photometric change of real_streets.py's third pass, written as a KITTI
   root (`neoslam.datasets.kitti_writer`, ground truth re-based to B's first frame), run into A's map.
4. Crash: a run on a simulated drive (KITTI 05 frames 0-799) SIGKILLed at seeded random moments after start-up
   (uniform between the moment its map file appears and the end of an uninterrupted run): the map opens, passes
   `PRAGMA integrity_check`, and its keyframes are a prefix (ids and centres) of the uninterrupted run's, and all of
   that run's keyframes before the last frame the killed map records as processed; then a later session on the same
   drive relocalises in one killed map that holds keyframes.
5. Cost: the whole of simulated KITTI 05 run without and with --map (creating it), alternately, median wall time of
   the process and of the SLAM loop; the time to open and load the 05 map; the start-up of a short run with and
   without the 05 map (--localise-only), whose difference is what loading costs a run.

6. A session that starts in the middle of the map: B = KITTI 05 frames 500-799 (its own noise, from the identity:
   no prior on where it is), run into A's map of part 1 (made here when part 1 did not run): the distance B drove
   from its first frame to its relocalisation, whether the relocalising closure is right, B's closures with A.
7. Lifelong mapping: one route (KITTI 00's ground truth cut where it comes back to its start) driven 1, 2 and 4 times
   in one session, each drive in a fresh process: the map must end the same, not a growing copy of it
   (benchmarks._lifelong).
8. Real images, later sessions that start part way into the mapped street: A = kitti_06_51's map; B from frames 10,
   20 and 30 forward, with the third pass's photometric change or a darker, noisier one, each into A's map with
   --localise-only (benchmarks._real_later_sessions).

    python -m benchmarks.sessions [--quick] [--out FILE] [--seed 1] [--kills 20] [--repeats 3]
                                  [--parts 1 2 3 4 5 6 7 8] [--keep DIR]

`--quick`: B of part 1 only to frame 1599, 08 to frame 399, 5 kills, one cost run each, the lifelong drives on the
built-in block route.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import signal
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from benchmarks import _lifelong, _real_later_sessions, harness
from benchmarks._real_later_sessions import Rebased
from benchmarks.harness import data_root
from benchmarks.real_streets import THIRD_PASS
from neoslam.commands.simulate import simulate_dataset
from neoslam.config import NeoSLAMConfig, SimulatorConfig, load_config
from neoslam.config.profiles import simulation_config
from neoslam.datasets.kitti import read_kitti_sequence
from neoslam.datasets.kitti_writer import write_kitti_sequence
from neoslam.datasets.replay import ReplayedSequence
from neoslam.datasets.simulated import read_dataset
from neoslam.evaluation.trajectory_metrics import absolute_trajectory_error, align, associate
from neoslam.geometry import SimilarityTransform, yaw_pitch_roll
from neoslam.io.trajectory_files import read_trajectory, read_tum
from neoslam.pipeline import run
from neoslam.sim.session_drives import session_recordings
from neoslam.store.map_file import MapFile
from neoslam.store.recording import MapRecorder
from neoslam.types import Trajectory

MAX_ATTEMPTS_PER_KILL = 3  # runs started per kill wanted, at most (a run may end before its moment)
SPLIT = 1200  # session A of KITTI 05 is frames 0 .. SPLIT-1, B the rest
ON_STREET_M = 10.0  # a B frame this close (horizontally) to an A frame is on a street A mapped
RELOCALISE_WITHIN_M = 30.0  # target: B relocalises within this much driving onto A's streets
MID_MAP_FRAMES = (500, 800)  # part 6: a session of KITTI 05 that starts in the middle of A's map (frames 0-1199)
RELOCALISE_MID_MAP_M = 40.0  # target: it relocalises within this much driving from its start
ATE_TARGET_M = 2.0  # target: B's ATE in A's frame
NEVER_MEET_FRAMES = 1200  # part 2: KITTI 08 frames 0 .. this-1
CRASH_FRAMES = 800  # part 4: KITTI 05 frames 0 .. this-1
KILLS = 20
REPEATS = 3  # part 5: runs of each kind
STARTUP_FRAMES = 30  # part 5: the short run whose start-up is timed
RUN_TIMEOUT_S = 1800.0


QUICK = "B of part 1 only to frame 1599, 08 to frame 399, 5 kills, one cost run each; part 7 on the block route"
PARTS = [1, 2, 3, 4, 5, 6, 7, 8]


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=int, default=1, help="world seed; the sessions' noise seeds follow from it")
    parser.add_argument("--kills", type=int, default=None, help=f"crash runs (default {KILLS}; --quick 5)")
    parser.add_argument("--repeats", type=int, default=None, help=f"cost runs of each kind (default {REPEATS})")
    parser.add_argument("--parts", nargs="+", type=int, default=PARTS, choices=PARTS)
    parser.add_argument("--keep", type=Path, help="work in this folder and keep it (datasets, results, maps)")
    _lifelong.arguments(parser.add_argument_group("part 7, lifelong"))


# --- running neoslam ---------------------------------------------------------------------------------------------


def _executable() -> str:
    beside = Path(sys.executable).parent / "neoslam"
    return str(beside) if beside.is_file() else str(shutil.which("neoslam"))


class RunFailed(RuntimeError):
    pass


def _command(data: Path, out: Path, map_path: Path | None, extra: list[str] = ()) -> list[str]:
    command = [_executable(), "run", str(data), "--out", str(out), "--quiet", *extra]
    return command + (["--map", str(map_path)] if map_path is not None else [])


def _run(data: Path, out: Path, map_path: Path | None, extra: list[str] = ()) -> tuple[dict[str, Any], float]:
    """metrics.json of a finished run, and the process's wall time, s; RunFailed with the command and its output."""
    command = _command(data, out, map_path, list(extra))
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RunFailed(f"$ {' '.join(command)}\nexit {done.returncode}\n{done.stdout}{done.stderr}")
    return json.loads((out / "metrics.json").read_text()), wall


def _closures(out: Path) -> list[dict[str, str]]:
    with (out / "loop_closures.csv").open(newline="") as handle:
        return list(csv.DictReader(handle))


def _copy_map(source: Path, target: Path) -> None:
    """A map file and its SQLite side files (write-ahead log), if any."""
    for suffix in ("", "-wal", "-shm", "-journal"):
        if Path(f"{source}{suffix}").exists():
            shutil.copy2(f"{source}{suffix}", f"{target}{suffix}")


def _load_map(path: Path, config: NeoSLAMConfig):
    with MapFile.open(path, config, read_only=True) as handle:
        return handle.load()


def _integrity(path: Path) -> str:
    """SQLite's own check of the file, opened read-only ("ok" when sound)."""
    try:
        connection = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            return "; ".join(str(row[0]) for row in connection.execute("PRAGMA integrity_check").fetchall())
        finally:
            connection.close()
    except sqlite3.Error as error:
        return f"sqlite3.{type(error).__name__}: {error}"


# --- ground truth ------------------------------------------------------------------------------------------------


def _kitti_truth(sequence: str, frame_period: float) -> Trajectory:
    kitti = data_root() / "kitti"
    times = kitti / "times" / f"{sequence}.txt"
    return read_trajectory(kitti / "poses" / f"{sequence}.txt", "kitti", times if times.is_file() else None,
                           frame_period=frame_period)  # fmt: skip


def _arc(positions: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


def _ate(estimate: Trajectory, truth: Trajectory, alignment: str, since: float | None = None) -> float | None:
    """ATE RMSE after associating by timestamp; `since`: only the poses from that time on."""
    matched_estimate, matched_truth = associate(estimate, truth, 0.01)
    if since is not None:
        keep = np.flatnonzero(matched_truth.timestamps >= since - 1e-6)
        if len(keep) < 3:
            return None
        matched_estimate, matched_truth = matched_estimate.subset(keep), matched_truth.subset(keep)
    return float(absolute_trajectory_error(matched_estimate, matched_truth, alignment).rmse)


def _fit(estimate: Trajectory, truth: Trajectory) -> SimilarityTransform:
    """The rigid transform that best aligns `estimate` onto `truth` (associated by timestamp)."""
    matched_estimate, matched_truth = associate(estimate, truth, 0.01)
    return align(matched_estimate, matched_truth, "se3")[1]


def _moved(trajectory: Trajectory, transform: SimilarityTransform) -> Trajectory:
    return Trajectory(trajectory.timestamps, transform.apply_to_poses(trajectory.poses))


def _split(estimate: Trajectory, truth: Trajectory) -> str:
    """Horizontal and vertical RMS of the unaligned position error (associated by timestamp)."""
    matched_estimate, matched_truth = associate(estimate, truth, 0.01)
    error = matched_estimate.positions - matched_truth.positions
    horizontal = np.sqrt((error[:, :2] ** 2).sum(axis=1).mean())
    return f"{horizontal:.2f} / {np.sqrt((error[:, 2] ** 2).mean()):.2f}"


def _pair(ate: dict[str, float]) -> str:
    return f"{ate['none']:.2f} / {ate['se3']:.2f}"


def _judge(rows: list[dict[str, str]], query_xy, match_xy, max_distance: float) -> tuple[int, int, float]:
    """(true, false, largest gap m) of closures, the query frame's and the match frame's true positions given by
    the callables."""
    gaps = [float(np.linalg.norm(query_xy(int(r["query_frame"])) - match_xy(int(r["match_frame"])))) for r in rows]
    true = sum(g <= max_distance for g in gaps)
    return true, len(gaps) - true, max(gaps, default=float("nan"))


def _first_on_streets(xy: np.ndarray, split: int, stop: int, radius: float) -> int | None:
    """The first frame of split .. stop-1 within `radius` (horizontally) of a frame before `split`, once the drive has
    left the end of those frames (it starts next to them): where B drives onto a street A mapped."""
    near, _ = cKDTree(xy[:split]).query(xy[split:stop])
    away = np.flatnonzero(near > radius)
    if not len(away):
        return None
    back = np.flatnonzero(near[away[0] :] <= radius)
    return split + int(away[0] + back[0]) if len(back) else None


def _session_block(metrics: dict[str, Any]) -> dict[str, Any]:
    if "session" not in metrics:
        raise RunFailed(f"metrics.json has no 'session' block: keys {sorted(metrics)}")
    return metrics["session"]


def _earlier(rows: list[dict[str, str]], session: int) -> list[dict[str, str]]:
    """The closures whose match keyframe belongs to an earlier session."""
    return [r for r in rows if int(r["match_session"]) != session]


# --- the parts ---------------------------------------------------------------------------------------------------


@dataclass
class Setup:
    work: Path
    seed: int
    quick: bool
    config: NeoSLAMConfig  # what the CLI runs with (defaults and NEOSLAM_* variables)
    simulator: SimulatorConfig  # vo odometry, real detection profile, the world seed

    @property
    def max_distance(self) -> float:
        return self.config.evaluation.loop_max_distance


def _simulate_sessions(
    setup: Setup, sequence: str, spans, world_seed: int, noise_seeds
) -> tuple[Trajectory, list[tuple[int, int]], list[Path]]:
    """Session datasets of a KITTI drive in the shared folder `sims` (simulated once, kept for the other parts):
    its ground truth, the spans (cut to the drive's length) and the dataset folders."""
    simulator = setup.simulator.model_copy(update={"seed": world_seed})
    truth = _kitti_truth(sequence, simulator.frame_period)
    spans = [(start, min(stop, len(truth))) for start, stop in spans]
    folder = setup.work / "sims"
    names = [
        f"kitti{sequence}_{a}_{b}_world{world_seed}_noise{n}" for (a, b), n in zip(spans, noise_seeds, strict=True)
    ]
    paths = [folder / name for name in names]
    if not all(path.exists() for path in paths):
        sessions = session_recordings(truth, spans, simulator, list(noise_seeds), f"kitti{sequence}")
        for path, session in zip(paths, sessions, strict=True):
            if not path.exists():
                simulate_dataset(path, session.recording)
    return truth, spans, paths


def _joint(truth: Trajectory, frames: np.ndarray, poses: np.ndarray) -> dict[str, float]:
    """ATE of poses at the given frames of `truth`, without alignment and with one SE(3) alignment for all."""
    estimate = Trajectory(truth.timestamps[frames], poses)
    reference = truth.subset(frames)
    return {mode: float(absolute_trajectory_error(estimate, reference, mode).rmse) for mode in ("none", "se3")}


def part_two_sessions(setup: Setup) -> dict[str, Any]:
    """KITTI 05 as sessions A and B in one world."""
    folder = setup.work / "p1"
    folder.mkdir(exist_ok=True)
    stop = SPLIT + 400 if setup.quick else 10**9
    seeds = (setup.seed + 1, setup.seed + 2)
    truth, spans, (data_a, data_b) = _simulate_sessions(setup, "05", [(0, SPLIT), (SPLIT, stop)], setup.seed, seeds)
    stop = spans[1][1]
    _, _, (data_whole,) = _simulate_sessions(setup, "05", [(0, stop)], setup.seed, seeds[:1])
    map_path = folder / "map.neoslam"
    metrics_a, wall_a = _run(data_a, folder / "RA", map_path)
    _copy_map(map_path, folder / "map_A.neoslam")  # A's map, for part 2
    metrics_b, wall_b = _run(data_b, folder / "RB", map_path)
    metrics_whole, _ = _run(data_whole, folder / "R_one_session", None)  # the baseline: one uninterrupted run
    session_a, session_b = _session_block(metrics_a), _session_block(metrics_b)

    xy = truth.positions[:, :2]
    onto_10 = _first_on_streets(xy, SPLIT, stop, ON_STREET_M)
    onto = _first_on_streets(xy, SPLIT, stop, setup.max_distance)
    relocalised = session_b.get("relocalised_frame")
    relocalised_05 = None if relocalised is None else SPLIT + int(relocalised)
    arc = _arc(truth.positions)

    def driven(frame: int | None) -> float | None:
        return None if relocalised_05 is None or frame is None else float(arc[relocalised_05] - arc[frame])

    rows_b = _closures(folder / "RB")
    with_a = _earlier(rows_b, int(session_b["id"]))
    true_a, false_a, worst_a = _judge(with_a, lambda q: xy[SPLIT + q], lambda m: xy[m], setup.max_distance)
    first_closure = min((SPLIT + int(r["query_frame"]) for r in with_a), default=None)

    estimate_b = read_tum(folder / "RB" / "trajectory_tum.txt")
    truth_b = truth.subset(np.arange(SPLIT, stop))  # in A's frame: 05's, whose first pose is the identity
    since = None if relocalised_05 is None else float(truth.timestamps[relocalised_05])
    estimate_a = read_tum(folder / "RA" / "trajectory_tum.txt")
    truth_a = truth.subset(np.arange(SPLIT))
    a_fit = _fit(estimate_a, truth_a)  # A's map frame against the truth: what B in A's frame can at best reach
    # A's part of the map as B left it (B's closures correct A's experiences too) and B's trajectory, together
    state = _load_map(map_path, setup.config)
    a_experiences = [e for e in state.experiences if e.session == int(session_a["id"])]
    a_frames = np.array([e.frame_index for e in a_experiences], dtype=int)
    a_poses = np.asarray(state.experience_poses)[[e.id for e in a_experiences]]
    b_frames = SPLIT + np.arange(len(estimate_b))
    both = np.concatenate([a_frames, b_frames])
    joint = _joint(truth, both, np.concatenate([a_poses, estimate_b.poses]))
    whole = read_tum(folder / "R_one_session" / "trajectory_tum.txt")
    one_session = _joint(truth, both, whole.poses[both])
    one_session_b = _joint(truth, b_frames, whole.poses[b_frames])
    result = {
        "A frames": f"0-{SPLIT - 1}",
        "B frames": f"{SPLIT}-{stop - 1}",
        "A keyframes stored": metrics_a.get("keyframes"),
        "B map_keyframes loaded": session_b.get("map_keyframes"),
        "B session id": session_b.get("id"),
        "B frame (map/session)": session_b.get("frame"),
        f"first B frame within {ON_STREET_M:g} m of A's route (05)": onto_10,
        f"first B frame within {setup.max_distance:g} m of A's route (05)": onto,
        "B relocalised at (B frame)": relocalised,
        "B relocalised at (05 frame)": relocalised_05,
        "B's first closure with A (05 frame)": first_closure,
        f"driven from {onto} to relocalisation m": driven(onto),
        f"driven from {onto_10} to relocalisation m": driven(onto_10),
        "B closures with A (true / false)": f"{true_a} / {false_a}",
        "B closures with A, largest true gap m": worst_a,
        "B map_closures (metrics)": session_b.get("map_closures"),
        "B closures within B": len(rows_b) - len(with_a),
        "B ATE in A's frame, no alignment m": _ate(estimate_b, truth_b, "none"),
        "B ATE in A's frame, no alignment: horizontal / vertical m": _split(estimate_b, truth_b),
        "B ATE in A's frame from relocalisation m": _ate(estimate_b, truth_b, "none", since) if since else None,
        "B ATE after A's own se3 alignment m": _ate(_moved(estimate_b, a_fit), truth_b, "none"),
        "B ATE se3 m": _ate(estimate_b, truth_b, "se3"),
        "B odometry ATE se3 m": metrics_b.get("ate_rmse_m", {}).get("odometry"),
        f"one uninterrupted run of 0-{stop - 1}, at B's frames: ATE no alignment / se3 m": _pair(one_session_b),
        "the same, no alignment: horizontal / vertical m": _split(whole.subset(b_frames), truth_b),
        "B's start (05 frame 1200): roll / pitch in A's frame, deg": "{:.2f} / {:.2f}".format(
            *np.degrees(yaw_pitch_roll(truth.poses[SPLIT]))[[2, 1]]
        ),
        "map after B (A's experiences + B's trajectory): ATE no alignment / se3 m": _pair(joint),
        "one uninterrupted run at the same frames: ATE no alignment / se3 m": _pair(one_session),
        "one uninterrupted run, whole: ATE se3 m (metrics)": metrics_whole.get("ate_rmse_m", {}).get("corrected"),
        "A ATE no alignment m": _ate(estimate_a, truth_a, "none"),
        "A ATE se3 m": _ate(estimate_a, truth_a, "se3"),
        "A relocalised_frame (new map)": session_a.get("relocalised_frame"),
        "run wall s (A / B)": f"{wall_a:.1f} / {wall_b:.1f}",
    }
    targets = {
        f"driven from {onto} to relocalisation m": f"<= {RELOCALISE_WITHIN_M:g}",
        "B closures with A (true / false)": "false 0",
        "B ATE in A's frame, no alignment m": f"<= {ATE_TARGET_M:g}",
    }
    return {"values": result, "targets": targets}


def _by_session(state, session: int) -> dict[str, Any]:
    """A session's part of a loaded map: keyframes, experiences, their corrected poses, links among them."""
    experiences = {e.id: e for e in state.experiences if e.session == session}
    keyframes = [k for k in state.keyframes if state.keyframe_experience.get(k.id) in experiences]
    ids = sorted(experiences)
    links = sorted(
        (link.source, link.target, str(link.kind), tuple(np.round(link.relative, 12).reshape(-1)))
        for link in state.links
        if link.source in experiences and link.target in experiences
    )
    return {
        "keyframes": keyframes,
        "experiences": [experiences[i] for i in ids],
        "poses": np.asarray(state.experience_poses)[ids] if ids else np.zeros((0, 4, 4)),
        "links": links,
    }


def _same_part(before: dict[str, Any], after: dict[str, Any]) -> dict[str, bool]:
    kb, ka = before["keyframes"], after["keyframes"]
    same_keyframes = len(kb) == len(ka) and all(
        a.id == b.id
        and a.frame_index == b.frame_index
        and a.labels == b.labels
        and np.array_equal(a.centers, b.centers)
        and np.array_equal(a.pose, b.pose)
        and np.array_equal(a.patches, b.patches)
        for a, b in zip(kb, ka, strict=True)
    )
    eb, ea = before["experiences"], after["experiences"]
    same_experiences = len(eb) == len(ea) and all(
        a.id == b.id and a.frame_index == b.frame_index and a.keyframe_id == b.keyframe_id
        and np.array_equal(a.pose, b.pose)
        for a, b in zip(eb, ea, strict=True)
    )  # fmt: skip
    same_poses = before["poses"].shape == after["poses"].shape and np.array_equal(before["poses"], after["poses"])
    return {"keyframes": same_keyframes, "experiences": same_experiences, "corrected poses": same_poses,
            "links": before["links"] == after["links"]}  # fmt: skip


def part_mid_map(setup: Setup) -> dict[str, Any]:
    """KITTI 05 frames MID_MAP_FRAMES, a session that starts in the middle of session A's map with no prior."""
    folder = setup.work / "p6"
    folder.mkdir(exist_ok=True)
    start, stop = MID_MAP_FRAMES
    seeds = (setup.seed + 1, setup.seed + 3)  # A's noise as in part 1, B's its own
    truth, _, (data_a, data_b) = _simulate_sessions(setup, "05", [(0, SPLIT), (start, stop)], setup.seed, seeds)
    map_path = folder / "map.neoslam"
    map_a = setup.work / "p1" / "map_A.neoslam"
    if map_a.exists():
        _copy_map(map_a, map_path)
    else:
        _run(data_a, folder / "RA", map_path)
    metrics_b, _ = _run(data_b, folder / "RB", map_path)
    session_b = _session_block(metrics_b)
    relocalised = session_b.get("relocalised_frame")
    xy = truth.positions[:, :2]
    with_a = _earlier(_closures(folder / "RB"), int(session_b["id"]))
    true_a, false_a, worst_a = _judge(with_a, lambda q: xy[start + q], lambda m: xy[m], setup.max_distance)
    first = min(with_a, key=lambda r: int(r["query_frame"]), default=None)
    first_right = None
    if first is not None:
        gap = np.linalg.norm(xy[start + int(first["query_frame"])] - xy[int(first["match_frame"])])
        first_right = bool(gap <= setup.max_distance)
    arc = _arc(truth.positions)
    driven = None if relocalised is None else float(arc[start + int(relocalised)] - arc[start])
    values = {
        "A frames": f"0-{SPLIT - 1}",
        "B frames (on A's streets from its first frame)": f"{start}-{stop - 1}",
        "B relocalised at (B frame)": relocalised,
        "driven from B's start to relocalisation m": driven,
        "B's relocalising closure right": first_right,
        "B closures with A (true / false)": f"{true_a} / {false_a}",
        "B closures with A, largest true gap m": worst_a,
    }
    targets = {
        "driven from B's start to relocalisation m": f"<= {RELOCALISE_MID_MAP_M:g}",
        "B's relocalising closure right": "True",
        "B closures with A (true / false)": "false 0",
    }
    return {"values": values, "targets": targets}


def part_never_meet(setup: Setup) -> dict[str, Any]:
    """KITTI 08 run into a copy of the map of 05's session A."""
    folder = setup.work / "p2"
    folder.mkdir(exist_ok=True)
    map_a = setup.work / "p1" / "map_A.neoslam"
    if not map_a.exists():
        raise RunFailed("part 2 needs part 1's map of session A (run with --parts 1 2)")
    frames = 400 if setup.quick else NEVER_MEET_FRAMES
    _, _, (data,) = _simulate_sessions(setup, "08", [(0, frames)], setup.seed + 7, (setup.seed + 8,))
    map_path = folder / "map.neoslam"
    _copy_map(map_a, map_path)
    before = _load_map(map_a, setup.config)
    metrics, wall = _run(data, folder / "R", map_path)
    session = _session_block(metrics)
    after = _load_map(map_path, setup.config)
    rows = _closures(folder / "R")
    a_id = before.sessions[0].id if before.sessions else 1
    same = _same_part(_by_session(before, a_id), _by_session(after, a_id))
    b_id = int(session["id"])
    result = {
        "B": f"KITTI 08 frames 0-{frames - 1}",
        "B relocalised_frame": session.get("relocalised_frame"),
        "B map_closures": session.get("map_closures"),
        "B closures with A (loop_closures.csv)": len(_earlier(rows, b_id)),
        "B closures within B": len(rows) - len(_earlier(rows, b_id)),
        "B frame": session.get("frame"),
        "A keyframes before / after": f"{len(_by_session(before, a_id)['keyframes'])} / "
        f"{len(_by_session(after, a_id)['keyframes'])}",
        "A experiences before / after": f"{len(_by_session(before, a_id)['experiences'])} / "
        f"{len(_by_session(after, a_id)['experiences'])}",
        "B keyframes in the map after": len(_by_session(after, b_id)["keyframes"]),
        "sessions in the map after": len(after.sessions),
        **{f"A's {name} identical": value for name, value in same.items()},
        "run wall s": round(wall, 1),
    }
    targets = {"B relocalised_frame": "None", "B map_closures": "0"}
    targets |= {f"A's {name} identical": "True" for name in same}
    return {"values": result, "targets": targets}


def part_real_images(setup: Setup) -> dict[str, Any]:
    folder = setup.work / "p3"
    folder.mkdir(exist_ok=True)
    root = data_root() / "kitti_06_51"
    base = read_kitti_sequence(root, "06")
    last = len(base) - 1
    order = tuple(range(last, -1, -1)) + tuple(range(1, last + 1))  # back to the start, then forward again
    replay = ReplayedSequence(base, order, (THIRD_PASS,) * len(order), label="back-forward")
    root_b = folder / "kitti_b"
    if not root_b.exists():
        write_kitti_sequence(root_b, "06", Rebased(replay))
    map_path = folder / "map.neoslam"
    metrics_a, wall_a = _run(root, folder / "RA", map_path, ["--sequence", "06"])
    metrics_b, wall_b = _run(root_b, folder / "RB", map_path, ["--sequence", "06"])
    session_b = _session_block(metrics_b)
    xy = base.ground_truth.positions[:, :2]
    rows = _closures(folder / "RB")
    with_a = _earlier(rows, int(session_b["id"]))
    true_a, false_a, worst = _judge(with_a, lambda q: xy[order[q]], lambda m: xy[m], setup.max_distance)
    relocalised = session_b.get("relocalised_frame")
    truth_b = replay.ground_truth  # in A's frame (06's, whose first pose is the identity)
    estimate_b = read_tum(folder / "RB" / "trajectory_tum.txt")
    since = None if relocalised is None else float(truth_b.timestamps[int(relocalised)])
    estimate_a = read_tum(folder / "RA" / "trajectory_tum.txt")
    result = {
        "B": f"frames {last}..0..{last} of kitti_06_51 ({len(order)}), third-pass photometric change",
        "A keyframes stored": metrics_a.get("keyframes"),
        "B map_keyframes loaded": session_b.get("map_keyframes"),
        "B relocalised at (B frame)": relocalised,
        "B relocalised at (06 frame)": None if relocalised is None else order[int(relocalised)],
        "B closures with A (true / false)": f"{true_a} / {false_a}",
        "B closures with A, largest gap m": worst,
        "B map_closures (metrics)": session_b.get("map_closures"),
        "B frame (map/session)": session_b.get("frame"),
        "B ATE in A's frame, no alignment m": _ate(estimate_b, truth_b, "none"),
        "B ATE in A's frame from relocalisation m": _ate(estimate_b, truth_b, "none", since) if since else None,
        "B ATE after A's own se3 alignment m": _ate(
            _moved(estimate_b, _fit(estimate_a, base.ground_truth)), truth_b, "none"
        ),
        "B ATE se3 m": _ate(estimate_b, truth_b, "se3"),
        "A ATE no alignment m": _ate(estimate_a, base.ground_truth, "none"),
        "run wall s (A / B)": f"{wall_a:.1f} / {wall_b:.1f}",
    }
    targets = {"B relocalised at (B frame)": "not None", "B closures with A (true / false)": "false 0"}
    return {"values": result, "targets": targets}


def _wait_for(path: Path, process: subprocess.Popen, start: float) -> float | None:
    """Seconds after `start` at which `path` appeared (None if the process ended first)."""
    while not path.exists():
        if process.poll() is not None:
            return None
        time.sleep(0.01)
    return time.perf_counter() - start


def _reference_run(data: Path, folder: Path) -> tuple[Path, float, float]:
    """An uninterrupted run: its map, when its map file appeared and when it ended (s after start)."""
    map_path = folder / "reference.neoslam"
    command = _command(data, folder / "R_reference", map_path)
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    appeared = _wait_for(map_path, process, start)
    out, err = process.communicate(timeout=RUN_TIMEOUT_S)
    ended = time.perf_counter() - start
    if process.returncode != 0 or appeared is None:
        raise RunFailed(f"$ {' '.join(command)}\nexit {process.returncode}\n{out}{err}")
    return map_path, appeared, ended


def _killed_run(data: Path, folder: Path, k: int, kill_at: float) -> dict[str, Any]:
    map_path = folder / f"killed_{k:02d}.neoslam"
    out = folder / f"R_killed_{k:02d}"
    process = subprocess.Popen(_command(data, out, map_path), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    start = time.perf_counter()
    appeared = _wait_for(map_path, process, start)
    while process.poll() is None and time.perf_counter() - start < kill_at:
        time.sleep(0.005)
    killed = process.poll() is None
    if killed:
        os.kill(process.pid, signal.SIGKILL)
    process.wait()
    return {"map": map_path, "out": out, "killed": killed, "kill_at_s": kill_at, "map_appeared_s": appeared,
            "returncode": process.returncode, "stderr": process.stderr.read().decode()[-500:]}  # fmt: skip


def _check_killed(run: dict[str, Any], reference, config: NeoSLAMConfig) -> dict[str, Any]:
    row = {"kill": run["kill"], "kill at s": round(run["kill_at_s"], 2), "killed": run["killed"]}
    if not run["map"].exists():
        return row | {"opens": "no file", "integrity": "-", "keyframes": 0, "prefix": "-"}
    try:
        state = _load_map(run["map"], config)
        row["opens"] = "yes"
    except Exception as error:  # noqa: BLE001 - the benchmark reports whatever the map file raises
        return row | {"opens": f"{type(error).__name__}: {error}"[:160], "integrity": _integrity(run["map"])}
    row["integrity"] = _integrity(run["map"])
    ids = [k.id for k in state.keyframes]
    ref_ids = [k.id for k in reference.keyframes]
    prefix = ids == ref_ids[: len(ids)] and all(
        np.array_equal(a.centers, b.centers) for a, b in zip(state.keyframes, reference.keyframes, strict=False)
    )
    frames = state.sessions[-1].frames if state.sessions else None
    # every keyframe the uninterrupted run made before the last frame this map records as processed
    committed = [k.id for k in reference.keyframes if frames is not None and k.frame_index < frames]
    row["complete"] = ids == committed
    return row | {"keyframes": len(ids), "prefix": prefix, "session frames": frames,
                  "results folder": "absent" if not run["out"].exists() else "present"}  # fmt: skip


def part_crash(setup: Setup, kills: int) -> dict[str, Any]:
    folder = setup.work / "p4"
    folder.mkdir(exist_ok=True)
    truth, _, (data,) = _simulate_sessions(setup, "05", [(0, CRASH_FRAMES)], setup.seed, (setup.seed + 1,))
    reference_map, appeared, ended = _reference_run(data, folder)
    reference = _load_map(reference_map, setup.config)
    rng = np.random.default_rng(setup.seed)
    rows: list[dict[str, Any]] = []
    # A moment drawn near the end may come after a run that went faster ends: draw until `kills` runs were killed.
    while sum(r["killed"] for r in rows) < kills and len(rows) < MAX_ATTEMPTS_PER_KILL * kills:
        k = len(rows)
        run = _killed_run(data, folder, k, float(rng.uniform(appeared, ended))) | {"kill": k + 1}
        rows.append(_check_killed(run, reference, setup.config))
    killed = [r for r in rows if r["killed"]]
    holding = [k for k, r in enumerate(rows) if r.get("keyframes", 0) > 0 and r.get("opens") == "yes"]
    later: dict[str, Any] = {}
    if holding:
        k = holding[0]
        map_path = folder / f"killed_{k:02d}.neoslam"
        later = {"killed map": k + 1, "its keyframes": rows[k]["keyframes"]}
        try:
            metrics, _ = _run(data, folder / "R_later", map_path)
        except RunFailed as error:
            later["run"] = f"FAILED: {error}".replace("\n", " ")
        else:
            session = _session_block(metrics)
            xy = truth.positions[:, :2]  # the drive starts at 05's first pose, the identity
            closures = _earlier(_closures(folder / "R_later"), int(session["id"]))
            true, false, _ = _judge(closures, lambda q: xy[q], lambda m: xy[m], setup.max_distance)
            later |= {"relocalised_frame": session.get("relocalised_frame"),
                      "map_closures": session.get("map_closures"),
                      "closures with the killed session (true / false)": f"{true} / {false}"}  # fmt: skip
    summary = {
        "drive": f"KITTI 05 frames 0-{CRASH_FRAMES - 1} (simulated)",
        "uninterrupted run s (map file after s)": f"{ended:.1f} ({appeared:.1f})",
        "reference keyframes": len(reference.keyframes),
        "runs / killed before the end": f"{len(rows)} / {len(killed)}",
        "maps that open": sum(r.get("opens") == "yes" for r in killed),
        "integrity ok": sum(r.get("integrity") == "ok" for r in killed),
        "keyframes a prefix of the reference": sum(r.get("prefix") is True for r in killed),
        "keyframes complete to the frames recorded": sum(r.get("complete") is True for r in killed),
        "killed with 0 keyframes": sum(r.get("keyframes", 0) == 0 for r in killed),
        "killed with no map file": sum(r.get("opens") == "no file" for r in killed),
        "results folder written (killed after it)": sum(r.get("results folder") == "present" for r in killed),
        **{f"later session: {key}": value for key, value in later.items()},
    }
    return {"values": summary, "rows": rows, "targets": {"runs / killed before the end": f">= {kills} killed"}}


def _load_time(map_path: Path, config: NeoSLAMConfig, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        _load_map(map_path, config)
        times.append(time.perf_counter() - start)
    return times


def _median_and_runs(values: list[float]) -> str:
    return f"{statistics.median(values):.1f} ({', '.join(f'{v:.1f}' for v in values)})"


def _writing_share(data: Path, map_path: Path, config: NeoSLAMConfig) -> tuple[float, float]:
    """One in-process run with the map recorder timed: seconds spent writing the map (every commit, the last one
    and closing) and seconds of NeoSLAM's steps. A ratio within one run holds on a loaded machine, where the ratio
    of two processes' wall times does not."""
    map_file = MapFile.create(map_path, config)
    map_file.load()
    recorder = MapRecorder(map_file)
    spent = [0.0]

    def timed(slam, frame, pose) -> None:
        start = time.perf_counter()
        recorder(slam, frame, pose)
        spent[0] += time.perf_counter() - start

    result = run(read_dataset(data, config.motion_limits).frames(), config, progress=False, on_step=timed)
    start = time.perf_counter()
    recorder.finish()
    map_file.close()
    return spent[0] + time.perf_counter() - start, float(result.frame_times_s.sum())


def part_cost(setup: Setup, repeats: int) -> dict[str, Any]:
    folder = setup.work / "p5"
    folder.mkdir(exist_ok=True)
    _, _, (data,) = _simulate_sessions(setup, "05", [(0, 10**9)], setup.seed, (setup.seed + 1,))
    load_before = os.getloadavg()
    walls: dict[str, list[float]] = {"without": [], "with": []}
    loops: dict[str, list[float]] = {"without": [], "with": []}
    map_05 = None
    for k in range(repeats):
        for kind in ("without", "with"):
            map_path = folder / f"map_{k}.neoslam" if kind == "with" else None
            metrics, wall = _run(data, folder / f"R_{kind}_{k}", map_path)
            walls[kind].append(wall)
            loops[kind].append(float(metrics["timing"]["wall_s"]))
            map_05 = map_path or map_05
    shares = [_writing_share(data, folder / f"timed_{k}.neoslam", setup.config) for k in range(repeats)]
    load_after = os.getloadavg()
    load_s = _load_time(map_05, setup.config, 3)
    state = _load_map(map_05, setup.config)
    short_folder = folder / "short"
    short_folder.mkdir(exist_ok=True)
    _, _, (short,) = _simulate_sessions(setup, "05", [(0, STARTUP_FRAMES)], setup.seed, (setup.seed + 3,))
    startup: dict[str, list[float]] = {"without": [], "with": []}
    for k in range(repeats):
        startup["without"].append(_run(short, short_folder / f"R_without_{k}", None)[1])
        startup["with"].append(_run(short, short_folder / f"R_with_{k}", map_05, ["--localise-only"])[1])
    median = {kind: statistics.median(values) for kind, values in walls.items()}
    loop_median = {kind: statistics.median(values) for kind, values in loops.items()}
    share = statistics.median(100 * written / steps for written, steps in shares)
    values = {
        "map writing, share of the steps' time (one in-process run; median of runs)": f"{share:.1f} %",
        "map writing s / steps s (runs)": ", ".join(f"{w:.2f} / {t:.1f}" for w, t in shares),
        "map_store.synchronous": setup.config.map_store.synchronous,
        "runs of each kind": repeats,
        "process wall s without --map (runs)": _median_and_runs(walls["without"]),
        "process wall s with --map (runs)": _median_and_runs(walls["with"]),
        "process ratio with / without": median["with"] / median["without"],
        "SLAM loop s without / with": f"{loop_median['without']:.1f} / {loop_median['with']:.1f}",
        "SLAM loop ratio with / without": loop_median["with"] / loop_median["without"],
        "05 map: keyframes / experiences": f"{len(state.keyframes)} / {len(state.experiences)}",
        "05 map file MB": round(map_05.stat().st_size / 1e6, 2),
        "load (MapFile.open + load) s, median of 3 (first)": f"{statistics.median(load_s):.3f} ({load_s[0]:.3f})",
        f"start-up + {STARTUP_FRAMES} frames s without map": statistics.median(startup["without"]),
        f"start-up + {STARTUP_FRAMES} frames s with the 05 map (--localise-only)": statistics.median(startup["with"]),
        "load average 1/5/15 min before": " ".join(f"{v:.2f}" for v in load_before),
        "load average 1/5/15 min after": " ".join(f"{v:.2f}" for v in load_after),
        "cores": os.cpu_count(),
    }  # fmt: skip
    targets = {
        "map writing, share of the steps' time (one in-process run; median of runs)": "<= 10 %",
        "process ratio with / without": "<= 1.10",
        "load (MapFile.open + load) s, median of 3 (first)": "< 2",
    }
    return {"values": values, "targets": targets}


# --- output ------------------------------------------------------------------------------------------------------


TITLES = {
    1: "1. KITTI 05 in two sessions (A 0-1199 makes the map, B from 1200 extends it)",
    2: "2. Routes that never meet (KITTI 08 into A's map)",
    3: "3. Real images: kitti_06_51, then played back and forward with photometric changes",
    4: "4. Crash: SIGKILL at random moments",
    5: "5. Cost of the map file",
    6: "6. A session that starts in the middle of the map (KITTI 05 frames 500-799 into A's map)",
    7: "7. Lifelong mapping: one route driven again and again",
    8: "8. Real images: later sessions that start part way into the mapped street of kitti_06_51",
}


def main(argv: list[str] | None = None) -> None:
    data = (("kitti", "poses"), ("kitti_06_51",), ("models", "yolox_nano_coco"))  # part 3 runs the real front end
    bench = harness.start(__name__, __doc__, QUICK, arguments, argv, data=data)
    args = bench.args
    kills = args.kills if args.kills is not None else (5 if args.quick else KILLS)
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else REPEATS)
    config = load_config()
    simulator = simulation_config(config, "vo", args.seed, "real").simulator
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        setup = Setup(work, args.seed, args.quick, config, simulator)
        parts = {
            1: lambda: part_two_sessions(setup),
            2: lambda: part_never_meet(setup),
            3: lambda: part_real_images(setup),
            4: lambda: part_crash(setup, kills),
            5: lambda: part_cost(setup, repeats),
            6: lambda: part_mid_map(setup),
            8: lambda: _real_later_sessions.run_part(setup.work / "p8", _run),
        }
        results: dict[str, Any] = {}
        for number in sorted(args.parts):
            started = time.perf_counter()
            if number == 7:  # a study of its own within one session: its tables, not a table of values
                print(f"## {TITLES[number]}\n", flush=True)
                results["7"] = _lifelong.run_part(bench, args) | {
                    "benchmark part s": round(time.perf_counter() - started, 1)
                }
                continue
            try:
                part = parts[number]()
            except Exception as error:  # noqa: BLE001 - a failed part is reported and the others run
                print(f"## {TITLES[number]}\n\nFAILED:\n\n```\n{type(error).__name__}: {error}\n```\n", flush=True)
                results[str(number)] = {"failed": str(error)}
                continue
            part["values"]["benchmark part s"] = round(time.perf_counter() - started, 1)
            targets = part.get("targets", {})
            rows = [{"quantity": k, "value": v, "target": targets.get(k, "")} for k, v in part["values"].items()]
            bench.table(f"part{number}", rows, ["quantity", "value", "target"], title=f"## {TITLES[number]}")
            if "rows" in part:
                columns = ["kill", "kill at s", "killed", "opens", "integrity", "keyframes", "prefix", "complete",
                           "session frames", "results folder"]  # fmt: skip
                bench.table(f"part{number}_runs", part["rows"], columns)
            if "sessions" in part:
                bench.table(f"part{number}_sessions", part["sessions"], list(part["sessions"][0]))
            results[str(number)] = part
    bench.finish({"seed": args.seed, "parts": json.loads(json.dumps(results, default=str))})


if __name__ == "__main__":
    main()
