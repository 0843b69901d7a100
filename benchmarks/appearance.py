"""Is appearance honest? The appearance patches of the real front end on kitti_06_51 against the simulator's.

The loop-closure matcher pairs two objects only when their 16x16 grey patches differ by at most
`matching.appearance_rmse_threshold` (RMSE, grey levels). This measures what that gate sees on real images, and
whether the simulator's patches behave the same way.

Real: the front end's detection and ORB stereo steps (default detector) on the 51 frames, and on the third pass of
the revisit real_streets.py builds (the frames played again through its photometric change: gain 0.8, offset +15,
noise sigma 3, blur sigma 0.7 px, shift (1.3, -0.8) px). Poses come from the ground truth (a benchmark may use
them; the SLAM path never does), so the front end runs without its stereo odometry, which does not change what it
detects and places. Each placed observation goes to the world with its frame's ground-truth pose; observations of
one label within 2.5 m (or 3 depth std) across frames are one object (benchmarks._street), and objects placed in
at least 2 frames count. A third-pass observation belongs to the nearest first-pass object of its label within the
same radius. Car pairs are compared:

  (a) the same car in two frames of the first pass,
  (b) two different cars of the first pass,
  (c) the same car, a first-pass frame against a third-pass frame (and, as a row of its own, the same frame in both
      passes: the images differ only by the photometric change).

Three descriptors: the patch RMSE (the matcher's formula), the zero-mean normalised cross-correlation of the
patches (ZNCC, insensitive to gain and offset) and ORB descriptors on the box (enlarged to at least 64 px high;
the distance of two boxes is the mean Hamming distance of their mutual best matches). How well each tells (a) from
(b), and (c) from different cars across the passes, is the ROC AUC (the chance that a same-car pair is closer than
a different-car pair), and the share of different-car pairs a gate lets through when it is set to let 90 % of the
same-car pairs through.

Simulated: `neoslam simulate` of the same poses (KITTI 06 frames 0-50, then played back and forward again as the
revisit is, the street laid along the poses beyond frame 50 as sim2real.py does) with the `real` profile, several
seeds; objects and their pairs from the truth object ids, car views of objects seen at least twice on the first
pass. A row is flagged (!) when the simulated median RMSE is not within 30 % of the real one.

Two grids of the simulator's appearance settings are simulated on the first pass (fewer seeds), and the best of
each is then run on all seeds and both passes:
- config: detection.patch_noise, patch_gain_sigma and texture_individuality (fields a --config file can set), the
  textures as they are; fitted to the 10th, 50th and 90th RMSE percentiles of rows (a) and (b);
- textures: the same fields and the texture contrast of neoslam.sim.world, its texture mean set to the real patches'
  median grey level; fitted to those percentiles and to the patches' median grey level and contrast.
"Best" is the smallest largest |log(simulated / real)| over the fitted figures. The texture constants are set for
the measurement only, at run time; no default changes.

Last, row (a) split by how much the viewing distance changed between the two views, real against simulated: the
real patch of a car changes with the view, the simulated one does not.

    python -m benchmarks.appearance [--quick] [--out FILE] [--seeds 1 2 ...]  (default seeds 1-5)
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.stats import rankdata

import neoslam.sim.world as sim_world
from benchmarks import harness
from benchmarks._street import (
    ASSOCIATION_RADIUS,
    ASSOCIATION_SIGMAS,
    MIN_REPEATS,
    SEQUENCE,
    RealRun,
    cluster_observations,
    depth_sigma,
    to_world,
)
from benchmarks.harness import data_root
from benchmarks.real_streets import THIRD_PASS
from benchmarks.sim2real import ODOMETRY, _street_poses
from neoslam.config import NeoSLAMConfig, SimulatorConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.kitti import KittiSequence, read_kitti_sequence
from neoslam.datasets.replay import ReplayedSequence, forward_back_forward
from neoslam.perception.frontend import open_front_end
from neoslam.sim.simulator import simulate
from neoslam.types import Frame, Trajectory

LABEL = "car"  # the matcher compares patches within a label; the street's objects are almost all cars
SEEDS, QUICK_SEEDS = [1, 2, 3, 4, 5], [1, 2]
TOLERANCE = 0.3  # a simulated median within 30 % of the real one
ACCEPT_SAME = 0.9  # the gate of the "different let through" column lets this share of same-object pairs through
ORB_MIN_HEIGHT = 64.0  # px: a box is enlarged to at least this height before ORB (distant cars are ~20 px high)
ORB_PATCH = 31  # px, OpenCV's ORB patch: the margin of image kept around the box
ORB_FEATURES = 200
ORB_FAST_THRESHOLD = 7  # lower than the stereo step's 12: small, low-contrast boxes need keypoints too
ORB_NO_MATCH = 256.0  # bits: the distance of two boxes that share no match (or have no keypoint)
# Grids of the simulator's appearance settings. Textures: the texture mean is the real patches' median grey level
# and the grid spans the texture contrast, patch noise, gain std and individuality. Config: the texture constants
# stay as they are and only the detection profile's fields (settable with --config) vary.
TEXTURE_GRID = {
    "contrast": (25.0, 30.0, 35.0),
    "patch_noise": (5.0, 10.0, 15.0),
    "patch_gain_sigma": (0.2, 0.3, 0.4),
    "texture_individuality": (0.8, 1.0),
}
CONFIG_GRID = {
    "patch_noise": (5.0, 10.0, 15.0, 20.0),
    "patch_gain_sigma": (0.1, 0.15, 0.2, 0.25),
    "texture_individuality": (0.3, 0.4, 0.5),
}
QUICK_TEXTURE_GRID = {
    "contrast": (25.0, 30.0),
    "patch_noise": (10.0, 15.0),
    "patch_gain_sigma": (0.2, 0.3),
    "texture_individuality": (0.8, 1.0),
}
QUICK_CONFIG_GRID = {"patch_noise": (10.0, 15.0), "patch_gain_sigma": (0.15, 0.2), "texture_individuality": (0.4, 0.5)}
GRID_SEEDS, QUICK_GRID_SEEDS = [1, 2], [1]
CHANGE_BANDS = ((0.0, 0.1), (0.1, 0.3), (0.3, 1.0), (1.0, np.inf))  # relative change of the viewing distance
ROWS = {
    "same": "(a) same car, two frames",
    "different": "(b) different cars",
    "across": "(c) same car, pass 1 vs replayed pass",
    "across_same_frame": "(c) same car, same frame in both passes",
}


@dataclass(frozen=True)
class View:
    """One observation of an object: which object (association or truth id), from which frame and pass, its patch
    and (real images only) its ORB descriptors."""

    object_id: int
    frame: int  # frame of the street (the base frame of a replayed one)
    passage: int  # 1: first pass, 3: the replayed pass
    patch: np.ndarray  # (s, s) grey levels
    depth: float  # m, of the placed centre
    orb: np.ndarray | None = None


# -- descriptors -----------------------------------------------------------------------------------------------------


def patch_rmse(query: np.ndarray, stored: np.ndarray) -> np.ndarray:
    """(n, m) RMSE between every query and stored patch, grey levels (the formula of loop.matching._patch_rmse)."""
    q = query.reshape(len(query), -1).astype(float)
    s = stored.reshape(len(stored), -1).astype(float)
    squared = (q**2).sum(1)[:, None] + (s**2).sum(1)[None, :] - 2 * q @ s.T
    return np.sqrt(np.maximum(squared, 0.0) / q.shape[1])


def patch_zncc(query: np.ndarray, stored: np.ndarray) -> np.ndarray:
    """(n, m) zero-mean normalised cross-correlation of every query and stored patch, -1 to 1."""

    def normalised(patches: np.ndarray) -> np.ndarray:
        flat = patches.reshape(len(patches), -1).astype(float)
        flat -= flat.mean(axis=1, keepdims=True)
        return flat / np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-9)

    return normalised(query) @ normalised(stored).T


def orb_descriptors(image: np.ndarray, box: np.ndarray) -> np.ndarray | None:
    """ORB descriptors of the keypoints inside a box of a grey image; the box with a margin is enlarged to at least
    ORB_MIN_HEIGHT px first, so that a distant car's box holds keypoints."""
    height, width = image.shape[:2]
    x1, y1, x2, y2 = (float(v) for v in box)
    scale = max(1.0, ORB_MIN_HEIGHT / max(y2 - y1, 1.0))
    margin = ORB_PATCH / scale  # image px that become an ORB patch once enlarged
    left, top = int(max(np.floor(x1 - margin), 0)), int(max(np.floor(y1 - margin), 0))
    right, bottom = int(min(np.ceil(x2 + margin), width)), int(min(np.ceil(y2 + margin), height))
    crop = image[top:bottom, left:right]
    if scale > 1.0:
        crop = cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
    mask = np.zeros(crop.shape[:2], np.uint8)
    rows = slice(int((y1 - top) * scale), int(np.ceil((y2 - top) * scale)))
    mask[rows, int((x1 - left) * scale) : int(np.ceil((x2 - left) * scale))] = 255
    orb = cv2.ORB_create(nfeatures=ORB_FEATURES, fastThreshold=ORB_FAST_THRESHOLD)
    _, descriptors = orb.detectAndCompute(crop, mask)
    return descriptors


_MATCHER = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True)


def orb_distance(first: np.ndarray | None, second: np.ndarray | None) -> float:
    """Mean Hamming distance of the mutual best matches between two boxes' ORB descriptors, bits."""
    if first is None or second is None:
        return ORB_NO_MATCH
    matches = _MATCHER.match(first, second)
    return float(np.mean([m.distance for m in matches])) if matches else ORB_NO_MATCH


# -- pairs -----------------------------------------------------------------------------------------------------------


@dataclass
class Pairs:
    """Descriptor distances of one set of view pairs (ZNCC kept as the correlation; ORB on real images only)."""

    rmse: np.ndarray
    zncc: np.ndarray
    orb: np.ndarray | None
    change: np.ndarray  # relative change of the viewing distance between the two views: |d1 - d2| / min(d1, d2)


def _pair_sets(views: list[View], with_orb: bool = False) -> dict[str, Pairs]:
    """The pairs of rows (a), (b), (c), (c, same frame) and the different-object pairs across the passes."""
    first = [v for v in views if v.passage == 1]
    third = [v for v in views if v.passage == 3]

    def distances(a: list[View], b: list[View], rows: np.ndarray, cols: np.ndarray) -> Pairs:
        if len(rows) == 0:
            return Pairs(np.empty(0), np.empty(0), np.empty(0) if with_orb else None, np.empty(0))
        pa, pb = np.array([v.patch for v in a]), np.array([v.patch for v in b])
        da, db = np.array([a[i].depth for i in rows]), np.array([b[j].depth for j in cols])
        change = np.abs(da - db) / np.minimum(da, db)
        rmse = patch_rmse(pa, pb)[rows, cols]
        zncc = patch_zncc(pa, pb)[rows, cols]
        orb = (
            np.array([orb_distance(a[i].orb, b[j].orb) for i, j in zip(rows, cols, strict=True)]) if with_orb else None
        )
        return Pairs(rmse, zncc, orb, change)

    ids1 = np.array([v.object_id for v in first])
    frames1 = np.array([v.frame for v in first])
    i, j = np.triu_indices(len(first), 1)
    same = ids1[i] == ids1[j]
    sets = {"same": distances(first, first, i[same], j[same]), "different": distances(first, first, i[~same], j[~same])}
    ids3 = np.array([v.object_id for v in third])
    frames3 = np.array([v.frame for v in third])
    grid_rows, grid_cols = np.meshgrid(np.arange(len(first)), np.arange(len(third)), indexing="ij")
    r, c = grid_rows.ravel(), grid_cols.ravel()
    across = ids1[r] == ids3[c] if len(third) else np.zeros(0, bool)
    same_frame = across & (frames1[r] == frames3[c]) if len(third) else across
    sets["across"] = distances(first, third, r[across], c[across])
    sets["across_same_frame"] = distances(first, third, r[same_frame], c[same_frame])
    sets["across_different"] = distances(first, third, r[~across], c[~across])
    return sets


def roc_auc(same: np.ndarray, different: np.ndarray) -> float:
    """The chance that a same-object distance is smaller than a different-object one (ties count half)."""
    if len(same) == 0 or len(different) == 0:
        return float("nan")
    ranks = rankdata(np.concatenate([same, different]))
    return float((ranks[len(same) :].sum() - len(different) * (len(different) + 1) / 2) / (len(same) * len(different)))


def let_through(same: np.ndarray, different: np.ndarray) -> float:
    """Share of the different-object distances within the gate that lets ACCEPT_SAME of the same-object ones
    through."""
    if len(same) == 0 or len(different) == 0:
        return float("nan")
    return float(np.mean(different <= np.quantile(same, ACCEPT_SAME)))


def _summary(values: np.ndarray, threshold: float | None = None) -> dict[str, float]:
    if len(values) == 0:
        return {"pairs": 0}
    p10, p50, p90 = np.percentile(values, [10, 50, 90])
    figures = {"pairs": int(len(values)), "p10": float(p10), "median": float(p50), "p90": float(p90)}
    if threshold is not None:
        figures["below"] = float(np.mean(values <= threshold))
    return figures


# -- the real front end ----------------------------------------------------------------------------------------------


def real_views(sequence: KittiSequence, replay: ReplayedSequence, config: NeoSLAMConfig) -> tuple[list[View], dict]:
    """Car views of the first and the replayed pass, each with its object, from the front end's detection and ORB
    stereo on the real images."""
    front_end = open_front_end(replay, config.perception, odometry=replay.ground_truth).front_end
    third_start = 2 * len(sequence) - 1
    passes = {1: range(len(sequence)), 3: range(third_start, len(replay))}
    frames: dict[int, list[Frame]] = {1: [], 3: []}
    descriptors: dict[int, np.ndarray | None] = {}
    for passage, indices in passes.items():
        for index in indices:
            left, right = replay.stereo_pair(index)
            frame = front_end.frame(index, float(replay.timestamps[index]), left, right)
            for obs in frame.observations:
                descriptors[id(obs)] = orb_descriptors(left, obs.box_left)
            frames[passage].append(replace(frame, index=replay.order[index]))
    truth = sequence.ground_truth
    clusters = cluster_observations(RealRun(frames[1], [], truth, sequence.camera))
    objects = [c for c in clusters if c.label == LABEL and len(c.frames) >= MIN_REPEATS]
    views = [
        View(k, f, 1, obs.patch, float(obs.center_camera[2]), descriptors[id(obs)])
        for k, cluster in enumerate(objects)
        for f, obs in zip(cluster.frames, cluster.observations, strict=True)
    ]
    positions = np.array([c.position for c in objects]).reshape(-1, 3)
    unassigned = 0
    for frame in frames[3]:
        taken: set[int] = set()
        for obs in frame.observations:
            if obs.label != LABEL:
                continue
            point = to_world(truth.poses[frame.index], obs.center_camera)[0]
            sigma = obs.depth_sigma or depth_sigma(float(obs.center_camera[2]), sequence.camera)
            gaps = np.linalg.norm(positions - point, axis=1)
            gaps[list(taken)] = np.inf
            best = int(np.argmin(gaps)) if len(gaps) else -1
            if best < 0 or gaps[best] > max(ASSOCIATION_RADIUS, ASSOCIATION_SIGMAS * sigma):
                unassigned += 1
                continue
            taken.add(best)
            views.append(View(best, frame.index, 3, obs.patch, float(obs.center_camera[2]), descriptors[id(obs)]))
    counts = {
        "objects": len(objects),
        "first-pass views": sum(v.passage == 1 for v in views),
        "replayed-pass views": sum(v.passage == 3 for v in views),
        "replayed-pass car observations with no first-pass object": unassigned,
        "car observations placed once (left out)": sum(
            len(c.frames) < MIN_REPEATS for c in clusters if c.label == LABEL
        ),
    }
    return views, counts


# -- the simulator ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Appearance:
    """The simulator's appearance settings: texture mean and contrast (module constants of neoslam.sim.world) and
    the detection profile's patch noise, gain std and texture individuality."""

    mean: float
    contrast: float
    patch_noise: float
    patch_gain_sigma: float
    texture_individuality: float

    def detection_update(self) -> dict[str, float]:
        return {
            "patch_noise": self.patch_noise,
            "patch_gain_sigma": self.patch_gain_sigma,
            "texture_individuality": self.texture_individuality,
        }

    def short(self) -> str:
        return (
            f"mean {self.mean:g}, contrast {self.contrast:g}, noise {self.patch_noise:g}, "
            f"gain {self.patch_gain_sigma:g}, individuality {self.texture_individuality:g}"
        )


def default_appearance() -> Appearance:
    """The `real` profile's appearance settings as they are."""
    detection = simulation_config(NeoSLAMConfig(), ODOMETRY, 0, "real").simulator.detection
    return Appearance(
        sim_world.TEXTURE_MEAN,
        sim_world.TEXTURE_CONTRAST,
        detection.patch_noise,
        detection.patch_gain_sigma,
        detection.texture_individuality,
    )


@contextmanager
def textures(mean: float, contrast: float) -> Iterator[None]:
    """The simulator's texture mean and contrast set for one measurement, restored afterwards."""
    saved = sim_world.TEXTURE_MEAN, sim_world.TEXTURE_CONTRAST
    sim_world.TEXTURE_MEAN, sim_world.TEXTURE_CONTRAST = mean, contrast
    try:
        yield
    finally:
        sim_world.TEXTURE_MEAN, sim_world.TEXTURE_CONTRAST = saved


def _simulator_config(seed: int, appearance: Appearance) -> SimulatorConfig:
    simulator = simulation_config(NeoSLAMConfig(), ODOMETRY, seed, "real").simulator
    detection = simulator.detection.model_copy(update=appearance.detection_update())
    return simulator.model_copy(update={"detection": detection})


@dataclass(frozen=True)
class Street:
    """What the simulator drives: the street's poses (beyond frame 50 as far as the camera sees, where its objects
    stand), the number of first-pass frames, and the revisit's order of frames with its times."""

    poses: Trajectory
    frames: int
    order: tuple[int, ...]
    timestamps: np.ndarray


def simulated_views(street: Street, seed: int, appearance: Appearance, replay: bool = True) -> list[View]:
    """Car views (truth object ids) of a simulation of the first pass and, with `replay`, of the replayed one; only
    objects seen at least twice on the first pass, as on the real street."""
    if replay:
        truth = Trajectory(street.timestamps, street.poses.poses[list(street.order)])
    else:
        truth = street.poses.subset(np.arange(street.frames))
    with textures(appearance.mean, appearance.contrast):
        config = _simulator_config(seed, appearance)
        recording = simulate(truth, config, name="kitti06-51", source="kitti/poses/06.txt", world_along=street.poses)
    third_start = 2 * street.frames - 1
    views = []
    for index, detections in enumerate(recording.detections):
        passage = 1 if index < street.frames else 3 if index >= third_start else 0
        if passage == 0:
            continue
        for d in detections:
            if d.object_id >= 0 and d.label == LABEL and recording.world.labels[d.object_id] == LABEL:
                frame = street.order[index] if replay else index
                views.append(View(d.object_id, frame, passage, d.patch, float(d.center_camera[2])))
    seen: dict[int, int] = {}
    for v in views:
        seen[v.object_id] = seen.get(v.object_id, 0) + (v.passage == 1)
    return [v for v in views if seen[v.object_id] >= MIN_REPEATS]


def _pooled(view_sets: list[list[View]]) -> dict[str, Pairs]:
    """Pairs of each seed's views (pairs never join two seeds), pooled."""
    per_seed = [_pair_sets(views) for views in view_sets]
    return {
        name: Pairs(
            *(np.concatenate([getattr(s[name], f) for s in per_seed]) for f in ("rmse", "zncc")),
            None,
            np.concatenate([s[name].change for s in per_seed]),
        )
        for name in per_seed[0]
    }


def patch_statistics(views: list[View]) -> dict[str, float]:
    """Median grey level and median contrast (std within a patch) of the first-pass patches."""
    flat = np.array([v.patch for v in views if v.passage == 1], dtype=float).reshape(-1, 256)
    return {"mean": float(np.median(flat.mean(axis=1))), "contrast": float(np.median(flat.std(axis=1)))}


TARGETS = ("(a) p10", "(a) median", "(a) p90", "(b) p10", "(b) median", "(b) p90", "patch mean", "contrast")


def fit_targets(sets: dict[str, Pairs], stats: dict[str, float]) -> np.ndarray:
    """RMSE p10, median, p90 of rows (a) and (b), the patches' median grey level and contrast (TARGETS)."""
    figures = [np.percentile(sets[row].rmse, [10, 50, 90]) for row in ("same", "different")]
    return np.concatenate([*figures, [stats["mean"], stats["contrast"]]])


def fit_appearance(
    street: Street, real: np.ndarray, settings: list[Appearance], seeds: list[int], fitted: int
) -> list[dict]:
    """Every setting simulated on the first pass, sorted by the largest |log(simulated / real)| over the first
    `fitted` TARGETS."""
    results = []
    for appearance in settings:
        view_sets = [simulated_views(street, seed, appearance, replay=False) for seed in seeds]
        simulated = fit_targets(_pooled(view_sets), patch_statistics([v for views in view_sets for v in views]))
        deviation = float(np.max(np.abs(np.log(simulated[:fitted] / real[:fitted]))))
        results.append({"appearance": appearance, "deviation": deviation, "targets": simulated.tolist()})
    return sorted(results, key=lambda r: r["deviation"])


def grid_settings(grid: dict[str, tuple[float, ...]], base: Appearance) -> list[Appearance]:
    """The settings of a grid: its fields varied over their values, the rest as in `base`."""
    return [replace(base, **dict(zip(grid, values, strict=True))) for values in itertools.product(*grid.values())]


# -- output ----------------------------------------------------------------------------------------------------------


def _span(figures: dict[str, float], digits: int = 1) -> str:
    if not figures.get("pairs"):
        return "-"
    return f"{figures['median']:.{digits}f} ({figures['p10']:.{digits}f} to {figures['p90']:.{digits}f})"


def _ratio(simulated: dict[str, float], real: dict[str, float]) -> tuple[str, bool]:
    if not simulated.get("pairs") or not real.get("pairs"):
        return "-", False
    ratio = simulated["median"] / real["median"]
    within = abs(ratio - 1.0) <= TOLERANCE
    return f"{ratio:.2f}" + ("" if within else " !"), within


def _band(low: float, high: float) -> str:
    return f">= {low:.0%}" if np.isinf(high) else f"{low:.0%}-{high:.0%}"


def _real_table(real: dict[str, Pairs], threshold: float) -> list[dict]:
    rows = []
    for key, name in ROWS.items():
        pairs = real[key]
        rmse = _summary(pairs.rmse, threshold)
        rows.append(
            {
                "pairs (real)": name,
                "n": rmse["pairs"],
                "RMSE median (p10 to p90)": _span(rmse),
                f"share RMSE <= {threshold:g}": round(rmse.get("below", float("nan")), 3),
                "ZNCC median (p10 to p90)": _span(_summary(pairs.zncc), 2),
                "ORB Hamming median (p10 to p90)": _span(_summary(pairs.orb)),
            }
        )
    return rows


def _separation_table(sources: dict[str, dict[str, Pairs]]) -> list[dict]:
    rows = []
    for source, sets in sources.items():
        descriptors = {"RMSE": lambda p: p.rmse, "ZNCC": lambda p: -p.zncc}
        if sets["same"].orb is not None:
            descriptors["ORB"] = lambda p: p.orb
        for name, distance in descriptors.items():
            same, different = distance(sets["same"]), distance(sets["different"])
            rows.append(
                {
                    "descriptor": f"{name} ({source})",
                    "AUC (a) vs (b)": round(roc_auc(same, different), 3),
                    "AUC (c) vs different cars across passes": round(
                        roc_auc(distance(sets["across"]), distance(sets["across_different"])), 3
                    ),
                    f"(b) let through at {ACCEPT_SAME:.0%} of (a)": round(let_through(same, different), 3),
                }
            )
    return rows


def _comparison_table(sources: dict[str, dict[str, Pairs]], threshold: float) -> list[dict]:
    rows = []
    for key, name in ROWS.items():
        figures = {source: _summary(sets[key].rmse, threshold) for source, sets in sources.items()}
        row: dict = {"RMSE of": name, "real": _span(figures["real"])}
        for source in list(sources)[1:]:
            ratio, within = _ratio(figures[source], figures["real"])
            row[source] = _span(figures[source])
            row[f"{source}: ratio"] = ratio
            row[f"{source}: within"] = within
        row[f"share <= {threshold:g}"] = " / ".join(f"{figures[s].get('below', float('nan')):.2f}" for s in sources)
        row["figures"] = figures
        rows.append(row)
    return rows


def _viewpoint_table(sources: dict[str, dict[str, Pairs]]) -> list[dict]:
    """Row (a) by the change of viewing distance between the two views: median RMSE and ZNCC per source."""
    rows = []
    for low, high in CHANGE_BANDS:
        row: dict = {"distance change": _band(low, high)}
        for source, sets in sources.items():
            pairs = sets["same"]
            inside = (pairs.change >= low) & (pairs.change < high)
            row[f"{source}: n"] = int(inside.sum())
            row[f"{source}: RMSE"] = f"{np.median(pairs.rmse[inside]):.1f}" if inside.any() else "-"
            row[f"{source}: ZNCC"] = f"{np.median(pairs.zncc[inside]):.2f}" if inside.any() else "-"
        rows.append(row)
    return rows


def _fit_table(real: np.ndarray, fits: dict[str, list[dict]], shown: int) -> list[dict]:
    rows = [{"grid": "real", **{n: f"{v:.1f}" for n, v in zip(TARGETS, real, strict=True)}}]
    for grid, results in fits.items():
        for fit in results[:shown]:
            rows.append(
                {
                    "grid": grid,
                    "setting": fit["appearance"].short(),
                    "largest deviation": f"{np.exp(fit['deviation']) - 1:.0%}",
                    **{n: f"{v:.1f}" for n, v in zip(TARGETS, fit["targets"], strict=True)},
                }
            )
    return rows


QUICK = f"seeds {QUICK_SEEDS}, smaller grids of the appearance settings"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", nargs="+", type=int, default=None, help="simulator seeds (default 1-5)")


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    args = bench.args
    seeds = args.seeds or (QUICK_SEEDS if args.quick else SEEDS)
    config = NeoSLAMConfig()
    threshold = config.matching.appearance_rmse_threshold

    sequence = read_kitti_sequence(data_root() / "kitti_06_51", SEQUENCE)
    if sequence.ground_truth is None:
        raise SystemExit("kitti_06_51: no poses/06.txt: the association needs the ground truth")
    replay = forward_back_forward(sequence, THIRD_PASS)
    views, counts = real_views(sequence, replay, config)
    real = _pair_sets(views, with_orb=True)
    real_stats = patch_statistics(views)
    real_targets = fit_targets(real, real_stats)

    simulator = simulation_config(NeoSLAMConfig(), ODOMETRY, 0, "real").simulator
    camera_range = simulator.detection.max_range or simulator.camera.max_range
    street = Street(_street_poses(len(sequence), camera_range), len(sequence), replay.order, replay.timestamps)
    default = default_appearance()
    grids = (QUICK_TEXTURE_GRID, QUICK_CONFIG_GRID) if args.quick else (TEXTURE_GRID, CONFIG_GRID)
    texture_grid, config_grid = grids
    grid_seeds = QUICK_GRID_SEEDS if args.quick else GRID_SEEDS
    fits = {
        "config": fit_appearance(street, real_targets, grid_settings(config_grid, default), grid_seeds, 6),
        "textures": fit_appearance(
            street,
            real_targets,
            grid_settings(texture_grid, replace(default, mean=round(real_stats["mean"]))),
            grid_seeds,
            len(TARGETS),
        ),
    }
    settings = {"sim default": default, "sim config fit": fits["config"][0]["appearance"]}
    settings["sim texture fit"] = fits["textures"][0]["appearance"]
    sources = {"real": real}
    for name, appearance in settings.items():
        sources[name] = _pooled([simulated_views(street, seed, appearance) for seed in seeds])

    print(f"kitti_06_51, label {LABEL!r}: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
    print(
        f"real patches: median grey level {real_stats['mean']:.1f}, median contrast (std within a patch) "
        f"{real_stats['contrast']:.1f}\n"
    )
    real_rows = _real_table(real, threshold)
    bench.table("real", real_rows, list(real_rows[0]))
    separation = _separation_table(sources)
    print()
    bench.table("separation", separation, list(separation[0]))
    comparison = _comparison_table(sources, threshold)
    print(
        f"\nRMSE median (p10 to p90), grey levels; simulated: profile real, seeds {seeds}; car views of objects seen "
        f"at least twice; ratio = simulated / real median, ! = not within {TOLERANCE:.0%}"
    )
    columns = ["RMSE of", "real"]
    for source in settings:
        columns += [source, f"{source}: ratio"]
    bench.table("sim_vs_real", comparison, [*columns, f"share <= {threshold:g}"])
    for name, appearance in settings.items():
        print(f"{name}: {appearance.short()}")
    viewpoint = _viewpoint_table({"real": real, "sim texture fit": sources["sim texture fit"]})
    print(
        "\nrow (a) by the change of viewing distance between the two views, |d1 - d2| / min(d1, d2): median RMSE, ZNCC"
    )
    bench.table("viewpoint", viewpoint, list(viewpoint[0]))
    fit_rows = _fit_table(real_targets, fits, 3)
    print(
        f"\nbest grid settings (first pass, seeds {grid_seeds}): largest deviation (the larger of sim / real and "
        "real / sim, less 1) over RMSE p10, median, p90 of (a) and (b), and for the texture grid the patch mean and "
        "contrast too"
    )
    bench.table("fit", fit_rows, ["grid", "setting", "largest deviation", *TARGETS])
    fitted = settings["sim config fit"]
    print(
        "\nas a --config file (detection fields only; the texture mean and contrast are constants of "
        "neoslam.sim.world):\nsimulator:\n  detection:\n"
        + "".join(f"    {k}: {v:g}\n" for k, v in fitted.detection_update().items())
    )
    bench.finish(
        {
            "label": LABEL,
            "threshold": threshold,
            "seeds": seeds,
            "counts": counts,
            "real_patches": real_stats,
            "real": real_rows,
            "separation": separation,
            "comparison": [{k: v for k, v in row.items() if ": ratio" not in k} for row in comparison],
            "viewpoint": viewpoint,
            "settings": {name: appearance.__dict__ for name, appearance in settings.items()},
            "grid_best": {
                grid: [
                    {"setting": f["appearance"].__dict__, "deviation": f["deviation"], "targets": f["targets"]}
                    for f in results[:10]
                ]
                for grid, results in fits.items()
            },
        },
    )


if __name__ == "__main__":
    main()
