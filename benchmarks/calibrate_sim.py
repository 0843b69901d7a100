"""Fit the simulator's `real` detection profile to what the real front end gives on kitti_06_51.

Runs the real front end (YOLOX-Nano, ORB stereo, stereo odometry) over the 51 real frames of KITTI 06 and measures,
with the ground-truth poses (allowed here: this is a benchmark, not the SLAM path):

- distinct objects: each observation moved to the world (ground-truth pose x observation), grouped by label within
  2.5 m (or 3 depth std) across frames; groups placed in at least 2 frames are objects, their fused positions the
  inverse-variance mean; single placements are false positives (rate per frame, their depth range);
- occlusion: the smallest share of a box covered by nearer objects' boxes at which the front end placed at most 10 %
  of the object-frames it hides;
- detection probability: for each object and frame, whether the simulator's geometry has it in view (centre in range
  and in the image, box clear of the image border, not hidden behind nearer objects) and whether the front end
  placed it; fitted as depth table x image-column factor (separable, by iterative proportional fitting);
- depth noise: observation depth against the fused position's depth in that frame, as a disparity std (px);
- the street: rows of objects (signed lateral offset from the path; objects per 100 m of the street along which a
  car in that row would be in view from some frame: a row far to the side is only seen well ahead), the lateral
  spread within a row, and the class mix.

With hand labels of the vehicles (tests/data/labels/kitti_06_51.json, frames 0, 5, ..., 50) the street (density,
rows, class mix) and the detection probability come from the labels instead: labels projected to the world with
their distance, the box centre's bearing and the ground-truth pose, then grouped; a labelled vehicle counts as
detected when an observation of its frame has its centre inside the label's box. Without them, the street is the
front end's own objects (a car it never places is not counted, and the detection probability is that of the objects
it placed at least twice: the two go together, so the simulated detections per frame still match).

Prints a table of the measurements and the profile as a Python snippet for `neoslam.config.calibration` (and as YAML for
a `--config` file).

    python -m benchmarks.calibrate_sim [--out FILE] [--labels FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml

from benchmarks import harness
from benchmarks._street import (
    MIN_REPEATS,
    RealRun,
    along_and_lateral,
    cluster_observations,
    run_real_front_end,
    to_world,
)
from benchmarks.harness import REPO_ROOT, data_root
from neoslam.config import DetectionNoiseConfig, NeoSLAMConfig, WorldConfig
from neoslam.sim.detections import DetectionSimulator
from neoslam.sim.visibility import column_offset
from neoslam.sim.world import CLASS_SIZES, KERB_EXTRA, World

LABELS = REPO_ROOT / "tests" / "data" / "labels" / "kitti_06_51.json"
DEPTH_EDGES = (1.0, 15.0, 25.0, 40.0, 60.0)  # m, bins of the detection-probability table
COLUMN_EDGES = (0.0, 0.4, 0.7, 1.0)  # share of the half image width, bins of the column factor
MIN_SAMPLES = 5  # object-frames a bin needs to enter a table
FIT_ROUNDS = 20  # iterative proportional fitting of depth table x column factor
PROBE_STEP = 1.0  # m: spacing of the probe cars that measure where a row is in view
MIN_ROW_OFFSET = 1.0  # m: least lateral offset of a row
ROW_GAP = 4.0  # m: objects whose lateral offsets differ by more start another row
MIN_JITTER = 0.3  # m: least lateral spread within a row
LABEL_RADIUS = 3.0  # m: labels of one vehicle from different frames (hand-estimated distances)
LABEL_RADIUS_SHARE = 0.15  # and this share of the labelled distance
OCCLUSION_COVERS = (0.5, 0.6, 0.7, 0.8, 0.9, 1.0)  # candidate shares of a box covered by nearer boxes that hide it
MAX_PLACED_WHEN_HIDDEN = 0.1  # the cover chosen hides object-frames of which the front end placed at most this share
MAD_TO_SIGMA = 1.4826
ROAD_CLEARANCE = 2.0  # m: a parked car's centre beside the driven car (two half car widths and a little; not fitted)
DEFAULT_SPACING = WorldConfig().spacing


QUICK = "the whole fit (it has no smaller mode: 51 real frames, about a minute)"


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--labels", type=Path, default=LABELS, help="hand labels of the vehicles (if present)")


# -- geometry of the simulator applied to the measured objects ------------------------------------------------------


def _street_heading(run: RealRun) -> float:
    """Direction of the (straight) street: from the first to the last true position."""
    dx, dy = run.truth.positions[-1, :2] - run.truth.positions[0, :2]
    return float(np.arctan2(dy, dx))


def _world_of(labels: list[str], surfaces: np.ndarray, heading: float) -> World:
    """Objects of the measured labels whose near (rear) surface is at the measured points: the centre lies half a
    length further along the street, which the car drives along."""
    sizes = np.array([CLASS_SIZES.get(label, CLASS_SIZES["car"]) for label in labels]).reshape(-1, 3)
    along = np.array([np.cos(heading), np.sin(heading), 0.0])
    centres = surfaces.reshape(-1, 3) + sizes[:, :1] / 2 * along
    n = len(labels)
    return World(
        np.array(labels, dtype=str), centres, sizes, np.full(n, heading), np.zeros((n, 3)), np.zeros((n, 1, 1))
    )


def _views(run: RealRun, world: World, config: NeoSLAMConfig, cover: float | None) -> list[dict]:
    """Per frame: object -> (depth, column offset) of the objects the simulator's geometry has in view."""
    stereo = config.perception.stereo
    noise = DetectionNoiseConfig(border_margin=stereo.border_margin, occlusion_cover=cover, max_range=stereo.max_depth)
    simulator = DetectionSimulator(world, run.camera, noise)
    return [
        {v.index: (v.depth, v.column) for v in simulator.in_view(run.truth.poses[i], 0.0)}
        for i in range(len(run.frames))
    ]


def _occlusion_cover(run: RealRun, world: World, config: NeoSLAMConfig, objects) -> tuple[float, list[dict]]:
    """The smallest cover at which the front end placed at most MAX_PLACED_WHEN_HIDDEN of the object-frames that
    occlusion by the other measured objects hides (objects it never placed hide nothing here)."""
    unhidden = _views(run, world, config, None)
    choices = []
    for cover in OCCLUSION_COVERS:
        views = _views(run, world, config, cover)
        hidden = [(k, f) for f, seen in enumerate(unhidden) for k in seen if k not in views[f]]
        placed = sum(f in objects[k].frames for k, f in hidden)
        choices.append({"cover": cover, "hidden_object_frames": len(hidden), "placed": placed})
        if placed <= MAX_PLACED_WHEN_HIDDEN * len(hidden):
            return cover, choices
    return OCCLUSION_COVERS[-1], choices


# -- fits --------------------------------------------------------------------------------------------------------------


def _bin(value: float, edges: tuple[float, ...]) -> int | None:
    index = int(np.searchsorted(edges, value, side="right")) - 1
    return index if 0 <= index < len(edges) - 1 else None


def _fit_tables(samples: list[tuple[float, float, bool]]) -> dict:
    """Detection probability by depth bin x factor by column bin from (depth, column, detected) samples."""
    rows = [(_bin(d, DEPTH_EDGES), _bin(c, COLUMN_EDGES), hit) for d, c, hit in samples]
    rows = [(a, b, hit) for a, b, hit in rows if a is not None and b is not None]
    depth_bins, column_bins = len(DEPTH_EDGES) - 1, len(COLUMN_EDGES) - 1
    probability, factor = np.full(depth_bins, 0.5), np.ones(column_bins)
    hits = np.zeros((depth_bins, column_bins))
    totals = np.zeros((depth_bins, column_bins))
    for a, b, hit in rows:
        totals[a, b] += 1
        hits[a, b] += hit
    for _ in range(FIT_ROUNDS):
        expected = totals @ factor
        probability = np.divide(hits.sum(axis=1), expected, out=np.zeros(depth_bins), where=expected > 0)
        probability = np.clip(probability, 0.0, 1.0)
        expected = probability @ totals
        factor = np.divide(hits.sum(axis=0), expected, out=np.ones(column_bins), where=expected > 0)
        factor /= max(factor.max(), 1e-9)
    depth_centres = [(a + b) / 2 for a, b in zip(DEPTH_EDGES, DEPTH_EDGES[1:], strict=False)]
    column_centres = [(a + b) / 2 for a, b in zip(COLUMN_EDGES, COLUMN_EDGES[1:], strict=False)]
    depth_n, column_n = totals.sum(axis=1), totals.sum(axis=0)
    return {
        "detection_probability": [
            (c, round(float(p), 2))
            for c, p, n in zip(depth_centres, probability, depth_n, strict=True)
            if n >= MIN_SAMPLES
        ],
        "column_factor": [
            (c, round(float(f), 2))
            for c, f, n in zip(column_centres, factor, column_n, strict=True)
            if n >= MIN_SAMPLES
        ],
        "depth_bins": [
            {"bin": f"{a:g}-{b:g} m", "object_frames": int(n), "placed": int(h)}
            for a, b, n, h in zip(DEPTH_EDGES, DEPTH_EDGES[1:], depth_n, hits.sum(axis=1), strict=False)
        ],
        "column_bins": [
            {"bin": f"{a:g}-{b:g}", "object_frames": int(n), "placed": int(h)}
            for a, b, n, h in zip(COLUMN_EDGES, COLUMN_EDGES[1:], column_n, hits.sum(axis=0), strict=False)
        ],
    }


def _disparity_sigma(run: RealRun, objects) -> tuple[float | None, int]:
    """Robust std of the disparity error of observations of repeated objects against their fused position."""
    fb = run.camera.fx * run.camera.baseline
    errors = []
    for cluster in objects:
        fused = cluster.position
        for frame, depth in zip(cluster.frames, cluster.depths, strict=True):
            pose = run.truth.poses[frame]
            robot = (fused - pose[:3, 3]) @ pose[:3, :3]
            expected = robot[0]  # the robot's x axis is the camera's depth axis
            errors.append(fb * (depth - expected) / expected**2)
    if len(errors) < MIN_SAMPLES:
        return None, len(errors)
    errors = np.array(errors)
    return float(MAD_TO_SIGMA * np.median(np.abs(errors - np.median(errors)))), len(errors)


def _in_view_length(run: RealRun, config: NeoSLAMConfig, offset: float, street: float) -> float:
    """Metres of street along which a car at this lateral offset would be in view (in range, in the image, not cut
    off) from at least one of the frames: objects of a row are counted over that stretch only."""
    heading = _street_heading(run)
    along = np.arange(0.0, street, PROBE_STEP)
    direction, left = np.array([np.cos(heading), np.sin(heading)]), np.array([-np.sin(heading), np.cos(heading)])
    xy = run.truth.positions[0, :2] + along[:, None] * direction + offset * left
    ground = run.truth.positions[0, 2] - run.camera.height_above_ground
    centres = np.column_stack([xy, np.full(len(xy), ground + CLASS_SIZES["car"][2] / 2)])
    probes = _world_of(["car"] * len(xy), centres - CLASS_SIZES["car"][0] / 2 * np.append(direction, 0.0), heading)
    seen = set().union(*_views(run, probes, config, None))
    return len(seen) * PROBE_STEP


def _rows(run: RealRun, config: NeoSLAMConfig, lateral: np.ndarray, street: float):
    """Rows of objects: (signed offset, objects per 100 m of the street along which the row is in view, lateral
    spread), and the slot spacing (shorter when a row is denser than one object per default spacing)."""
    offsets = np.sort(lateral)
    groups = []
    for side in (offsets[offsets < 0], offsets[offsets > 0]):
        if len(side):
            groups += np.split(side, np.flatnonzero(np.diff(side) > ROW_GAP) + 1)
    if not groups:
        return [], DEFAULT_SPACING
    rows = []
    for group in groups:
        offset = float(np.median(group))
        length = max(_in_view_length(run, config, offset, street), PROBE_STEP)
        jitter = max(MIN_JITTER, float(np.sqrt(np.mean((group - offset) ** 2))))
        rows.append((round(offset, 1), round(100.0 * len(group) / length, 1), round(jitter, 2)))
    densest = max(density for _, density, _ in rows)
    return rows, min(DEFAULT_SPACING, float(np.floor(100.0 / densest * 100) / 100))  # density x spacing <= 100


def _class_mix(labels: list[str]) -> dict[str, float]:
    names, counts = np.unique(labels, return_counts=True)
    return {str(n): round(float(c) / len(labels), 2) for n, c in zip(names, counts, strict=True)} or {"car": 1.0}


# -- hand labels -----------------------------------------------------------------------------------------------------


def _read_labels(path: Path) -> dict[int, list[dict]] | None:
    if not path.is_file():
        return None
    frames = json.loads(path.read_text())["frames"]
    return {int(frame): [v for v in vehicles if not v.get("doubtful", False)] for frame, vehicles in frames.items()}


def _label_point(run: RealRun, frame: int, vehicle: dict) -> np.ndarray:
    """World point of a label: at its depth (distance_m, along the optical axis) on the ray through its box centre."""
    cam = run.camera
    x1, y1, x2, y2 = vehicle["box"]
    ray = np.array([((x1 + x2) / 2 - cam.cx) / cam.fx, ((y1 + y2) / 2 - cam.cy) / cam.fy, 1.0])
    return to_world(run.truth.poses[frame], ray * float(vehicle["distance_m"]))[0]


def _label_objects(run: RealRun, labels: dict[int, list[dict]]) -> tuple[list[str], np.ndarray]:
    """Distinct labelled vehicles: labels of one class grouped across frames by world position."""
    names: list[str] = []
    points: list[list[np.ndarray]] = []
    for frame in sorted(labels):
        for vehicle in labels[frame]:
            point = _label_point(run, frame, vehicle)
            radius = max(LABEL_RADIUS, LABEL_RADIUS_SHARE * float(vehicle["distance_m"]))
            near = [
                (float(np.linalg.norm(np.mean(p, axis=0) - point)), k)
                for k, p in enumerate(points)
                if names[k] == vehicle["label"]
            ]
            near = [(d, k) for d, k in near if d < radius]
            if near:
                points[min(near)[1]].append(point)
            else:
                names.append(vehicle["label"])
                points.append([point])
    return names, np.array([np.mean(p, axis=0) for p in points]).reshape(-1, 3)


def _label_samples(run: RealRun, labels: dict[int, list[dict]], max_range: float) -> list[tuple[float, float, bool]]:
    """(depth, column offset, detected) of every labelled object the simulator would have in view (not truncated,
    not largely occluded, within range). Each observation of the frame detects at most one label: of those whose box
    holds its projected centre, the one nearest in depth."""
    cam = run.camera
    samples = []
    for frame, vehicles in sorted(labels.items()):
        if frame >= len(run.frames):
            continue
        usable = [
            v
            for v in vehicles
            if not v.get("truncated")
            and int(v.get("occluded", 0)) < 2
            and cam.min_range <= float(v["distance_m"]) <= max_range
        ]
        hit = [False] * len(usable)
        for obs in run.frames[frame].observations:
            x, y, z = obs.center_camera
            u, w = cam.fx * x / z + cam.cx, cam.fy * y / z + cam.cy
            holding = [
                (abs(float(v["distance_m"]) - z), k)
                for k, v in enumerate(usable)
                if v["box"][0] <= u <= v["box"][2] and v["box"][1] <= w <= v["box"][3]
            ]
            if holding:
                hit[min(holding)[1]] = True
        for v, detected in zip(usable, hit, strict=True):
            samples.append((float(v["distance_m"]), column_offset((v["box"][0] + v["box"][2]) / 2, cam), detected))
    return samples


# -- the whole calibration ---------------------------------------------------------------------------------------------


def calibrate(run: RealRun, config: NeoSLAMConfig, labels: dict[int, list[dict]] | None) -> dict:
    clusters = cluster_observations(run)
    objects = [c for c in clusters if len(c.frames) >= MIN_REPEATS]
    singles = [c for c in clusters if len(c.frames) < MIN_REPEATS]
    frames = len(run.frames)
    length = run.truth.path_length()
    heading = _street_heading(run)
    positions = np.array([c.position for c in objects]).reshape(-1, 3)
    world = _world_of([c.label for c in objects], positions, heading)
    cover, cover_choices = _occlusion_cover(run, world, config, objects)
    views = _views(run, world, config, cover)
    samples, outside = [], 0
    for k, cluster in enumerate(objects):
        for frame in range(frames):
            placed = frame in cluster.frames
            if k in views[frame]:
                samples.append((*views[frame][k], placed))
            else:
                outside += placed
    source = "front end objects"
    street_labels, street_points = [c.label for c in objects], positions
    if labels is not None:
        source = "hand labels"
        street_labels, street_points = _label_objects(run, labels)
        samples = _label_samples(run, labels, config.perception.stereo.max_depth)
    tables = _fit_tables(samples)
    along, lateral = along_and_lateral(run.truth, street_points)
    street = length + config.perception.stereo.max_depth  # the street in view from the driven stretch
    inside = (along >= 0) & (along <= street)
    # The simulator puts bicycles, people and trucks further out than the row by KERB_EXTRA: take it off here.
    extra = np.array([KERB_EXTRA.get(label, 0.0) for label in street_labels]).reshape(-1)
    kerb = np.sign(lateral) * np.maximum(np.abs(lateral) - extra, MIN_ROW_OFFSET)
    rows, spacing = _rows(run, config, kerb[inside], street)
    sigma, sigma_n = _disparity_sigma(run, objects)
    false_depths = [d for c in singles for d in c.depths]
    observations = sum(len(f.observations) for f in run.frames)
    return {
        "source": source,
        "frames": frames,
        "path_length_m": round(length, 1),
        "detector_boxes_per_frame": round(float(np.mean(run.boxes_per_frame)), 2) if run.boxes_per_frame else None,
        "observations_per_frame": round(observations / frames, 2),
        "objects": len(objects),
        "street_m": round(street, 1),
        "street_objects": int(inside.sum()),
        "placements_outside_simulated_view": outside,
        "false_positives": len(singles),
        "disparity_samples": sigma_n,
        "tables": tables,
        "occlusion": cover_choices,
        "profile": {
            "detection": {
                "detection_probability": tables["detection_probability"] or None,
                "column_factor": tables["column_factor"] or None,
                "max_range": config.perception.stereo.max_depth,
                "border_margin": config.perception.stereo.border_margin,
                "occlusion_cover": cover,
                "false_positives_per_frame": round(len(singles) / frames, 3),
                "false_positive_depth": (
                    (round(min(false_depths), 1), round(max(false_depths), 1)) if false_depths else None
                ),
                **({"disparity_sigma": round(sigma, 2)} if sigma is not None else {}),
            },
            "world": {
                "rows": rows,
                "spacing": spacing,
                "road_clearance": ROAD_CLEARANCE,
                "class_mix": _class_mix(street_labels),
            },
        },
    }


def _python_snippet(profile: dict) -> str:
    def body(name: str, values: dict) -> str:
        items = "\n".join(f"    {key}={value!r}," for key, value in values.items())
        return f"{name}(\n{items}\n)"

    return "\n".join(
        [
            "_REAL_DETECTION = " + body("DetectionNoiseConfig", profile["detection"]),
            "_REAL_WORLD = " + body("WorldConfig", profile["world"]),
        ]
    )


def _yaml_snippet(profile: dict) -> str:
    def plain(value):
        if isinstance(value, tuple | list):
            return [plain(v) for v in value]
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        return value

    section = {"simulator": {"detection_profile": "real", **plain(profile)}}
    return yaml.safe_dump(section, sort_keys=False, default_flow_style=None)


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(
        __name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("models", "yolox_nano_coco"))
    )
    args = bench.args
    config = NeoSLAMConfig()
    run = run_real_front_end(data_root() / "kitti_06_51", config)
    labels = _read_labels(args.labels)
    result = calibrate(run, config, labels)
    # The fitted values must make a valid profile.
    DetectionNoiseConfig(**result["profile"]["detection"])
    WorldConfig(**result["profile"]["world"])
    summary = [
        {"measure": key, "value": result[key]}
        for key in (
            "source",
            "frames",
            "path_length_m",
            "detector_boxes_per_frame",
            "observations_per_frame",
            "objects",
            "street_m",
            "street_objects",
            "placements_outside_simulated_view",
            "false_positives",
            "disparity_samples",
        )
    ]
    bench.table("summary", summary, ["measure", "value"])
    print()
    bench.table("depth_bins", result["tables"]["depth_bins"], ["bin", "object_frames", "placed"])
    print()
    bench.table("column_bins", result["tables"]["column_bins"], ["bin", "object_frames", "placed"])
    print()
    bench.table("occlusion", result["occlusion"], ["cover", "hidden_object_frames", "placed"])
    print()
    print("# neoslam.config.calibration, the `real` profile (python -m benchmarks.calibrate_sim):")
    print(_python_snippet(result["profile"]))
    print()
    print("# or as a --config file:")
    print(_yaml_snippet(result["profile"]))
    bench.finish(result)


if __name__ == "__main__":
    main()
