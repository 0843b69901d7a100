"""The real stereo odometry's error on every real frame with a reference, against the simulator's `vo` profile.

- KITTI 06 frames 0-50 (kitti_06_51; kitti_mini is its first 12 frames): the real front end's stereo odometry
  (ORB stereo, PnP) against the ground-truth poses; the same 51 poses simulated with the `vo` profile (seeds 1-10)
  against the same truth.
- EuRoC V1_01 frames 0-94 (euroc_v101_micro, rectified as read): no ground truth, but the gyro says whether the MAV
  moved. Over these 4.7 s its rate stays within a few mrad of its mean (the gyro's bias), so the MAV stands still
  and all the motion the odometry reports is error.

Per frame, the odometry's step is compared with the truth's (E = inv(dT_truth) dT_odometry, in the robot's axes:
x forward, y left, z up): the yaw of E, and its translation along (x) and across (y) the path. The odometry's
error as random walks (what the simulator draws and the pose graph's odometry links assume): heading in rad per
root second sqrt(mean(yaw^2) / dt), position likewise from the translation's norm; and per root metre at the
stretch's mean speed, beside the pose graph's stated rates (`experience_map.odometry_yaw_sigma_per_root_metre`,
`odometry_sigma_per_root_metre`) which the online estimate can only raise. End drift: the last pose's error after
the first poses are made to coincide, as a share of the path and in degrees of yaw. And what the online estimate of
the moving-object tracks (`mapping.odometry_noise`) gives at the end of the real frames, through the pipeline.

A real row is flagged (!) when it is outside the range of the simulated seeds.

    python -m benchmarks.real_odometry [--quick] [--seeds 1 2 ...] [--out FILE]   (default seeds 1-10)
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks import harness
from benchmarks._street import run_real_front_end
from benchmarks.harness import data_root
from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.euroc import read_euroc
from neoslam.geometry import integrate_body_velocities, invert_pose
from neoslam.perception.frontend import open_front_end
from neoslam.pipeline import NeoSLAM
from neoslam.sim.simulator import simulate
from neoslam.types import Frame, Trajectory

SEEDS, QUICK_SEEDS = list(range(1, 11)), [1, 2, 3]
QUICK = "seeds 1-3"
PROFILE = "vo"
EUROC_IMU = ("mav0", "imu0", "data.csv")
NS_PER_S = 1e9
NOT_APPLICABLE = "–"
STILL_RAD = 0.01  # the gyro's integrated rate about its mean stays within this: the MAV did not turn
COLUMNS = [
    "source", "frames", "path m", "yaw rms mrad", "along rms cm", "across rms cm", "heading mrad/sqrt(s)",
    "position cm/sqrt(s)", "heading mrad/sqrt(m)", "position cm/sqrt(m)", "end drift %", "end drift m", "end yaw deg",
]  # fmt: skip


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seeds", type=int, nargs="+", help=f"simulation seeds (default {SEEDS[0]}-{SEEDS[-1]})")


def step_errors(odometry: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per frame step, the odometry's error E = inv(dT_truth) dT_odometry: (n - 1, 4) yaw (rad), x, y, z (m)."""
    step_truth = invert_pose(truth[:-1]) @ truth[1:]
    step_odometry = invert_pose(odometry[:-1]) @ odometry[1:]
    error = invert_pose(step_truth) @ step_odometry
    yaw = Rotation.from_matrix(error[:, :3, :3]).as_rotvec()[:, 2]
    return np.column_stack([yaw, error[:, :3, 3]])


def odometry_figures(source: str, odometry: np.ndarray, truth: Trajectory) -> dict:
    """The row of one odometry against its reference poses (same frames)."""
    errors = step_errors(odometry, truth.poses)
    dt = float(np.mean(np.diff(truth.timestamps)))
    steps = np.linalg.norm(np.diff(truth.positions, axis=0), axis=1)
    path = float(steps.sum())
    heading = float(np.sqrt(np.mean(errors[:, 0] ** 2) / dt))
    position = float(np.sqrt(np.mean(np.sum(errors[:, 1:] ** 2, axis=1)) / dt))
    end = invert_pose(invert_pose(truth.poses[0]) @ truth.poses[-1]) @ (invert_pose(odometry[0]) @ odometry[-1])
    root_seconds_per_metre = np.sqrt(dt / np.mean(steps)) if path > 0 else np.nan
    return {
        "source": source,
        "frames": len(odometry),
        "path m": path,
        "yaw rms mrad": 1e3 * float(np.sqrt(np.mean(errors[:, 0] ** 2))),
        "along rms cm": 1e2 * float(np.sqrt(np.mean(errors[:, 1] ** 2))),
        "across rms cm": 1e2 * float(np.sqrt(np.mean(errors[:, 2] ** 2))),
        "heading mrad/sqrt(s)": 1e3 * heading,
        "position cm/sqrt(s)": 1e2 * position,
        "heading mrad/sqrt(m)": 1e3 * heading * root_seconds_per_metre,
        "position cm/sqrt(m)": 1e2 * position * root_seconds_per_metre,
        "end drift %": 100 * float(np.linalg.norm(end[:3, 3])) / path if path > 0 else None,
        "end drift m": float(np.linalg.norm(end[:3, 3])),
        "end yaw deg": float(np.degrees(abs(Rotation.from_matrix(end[:3, :3]).as_rotvec()[2]))),
    }


def online_estimate(frames: list[Frame], config: NeoSLAMConfig) -> tuple[float, float] | None:
    """What the moving-object tracks estimate of the odometry's noise after the frames (None: too few views)."""
    slam = NeoSLAM(config)
    for frame in frames:
        slam.step(frame)
    return slam.moving_objects.noise_estimate.noise()


def simulated_odometry(truth: Trajectory, seed: int) -> np.ndarray:
    """The `vo` profile's odometry poses along `truth` (integrated from the identity, as a dataset's frames are)."""
    config = simulation_config(NeoSLAMConfig(), PROFILE, seed, "real")
    recording = simulate(truth, config.simulator, name="kitti06-51", source="kitti/poses/06.txt")
    return integrate_body_velocities(recording.linear_velocity, recording.angular_velocity, truth.timestamps)


def euroc_row(config: NeoSLAMConfig) -> tuple[dict, float]:
    """The odometry of the EuRoC frames against standing still, and how far the gyro turned about its mean (rad)."""
    root = data_root() / "euroc_v101_micro"
    sequence = read_euroc(root, config.perception)
    frames = list(open_front_end(sequence, config.perception).frames())
    stamps = np.asarray(sequence.timestamps, dtype=float)
    still = Trajectory(stamps, np.repeat(np.eye(4)[None], len(stamps), axis=0))
    row = odometry_figures("EuRoC V1_01 0-94, real (standing)", np.array([f.odometry_pose for f in frames]), still)
    for column in ("path m", "end drift %", "heading mrad/sqrt(m)", "position cm/sqrt(m)"):
        row[column] = NOT_APPLICABLE  # standing: no path to divide by (the end drift in metres is kept)
    imu = np.loadtxt(root.joinpath(*EUROC_IMU), delimiter=",", comments="#")
    seconds = (imu[:, 0] - imu[0, 0]) / NS_PER_S
    window = (imu[:, 0] / NS_PER_S >= stamps[0]) & (imu[:, 0] / NS_PER_S <= stamps[-1])
    rates = imu[window, 1:4]
    turned = np.cumsum(rates - rates.mean(axis=0), axis=0) * float(np.mean(np.diff(seconds[window])))
    return row, float(np.abs(turned).max())


def _flag(row: dict, simulated: list[dict]) -> str:
    """Columns of a real row outside the simulated seeds' range."""
    outside = []
    for column in COLUMNS[3:]:
        values = [s[column] for s in simulated if isinstance(s[column], float)]
        if isinstance(row.get(column), float) and values and not min(values) <= row[column] <= max(values):
            outside.append(column)
    return ", ".join(outside)


def main(argv: list[str] | None = None) -> None:
    bench = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",), ("euroc_v101_micro",)))
    seeds = bench.args.seeds or (QUICK_SEEDS if bench.args.quick else SEEDS)
    config = NeoSLAMConfig()
    real = run_real_front_end(data_root() / "kitti_06_51", config)
    real_odometry = np.array([frame.odometry_pose for frame in real.frames])
    kitti = odometry_figures("KITTI 06 0-50, real", real_odometry, real.truth)
    estimate = online_estimate(real.frames, config)
    simulated = [
        odometry_figures(f"KITTI 06 0-50, {PROFILE} seed {seed}", simulated_odometry(real.truth, seed), real.truth)
        for seed in seeds
    ]
    median = {c: float(np.median([s[c] for s in simulated])) for c in COLUMNS[2:]}
    median |= {"source": f"KITTI 06 0-50, {PROFILE} (median of {len(seeds)} seeds)", "frames": len(real_odometry)}
    kitti["outside the simulated seeds"] = _flag(kitti, simulated)
    euroc, turned = euroc_row(config)
    stated = config.experience_map
    stated_row = dict.fromkeys(COLUMNS, NOT_APPLICABLE) | {
        "source": "pose graph, stated rates",
        "heading mrad/sqrt(m)": 1e3 * stated.odometry_yaw_sigma_per_root_metre,
        "position cm/sqrt(m)": 1e2 * stated.odometry_sigma_per_root_metre,
    }
    rows = [kitti, median, euroc, stated_row]
    print(f"## Odometry error per frame step: real stereo odometry and the simulator's `{PROFILE}` profile\n")
    print("Yaw and translation (along, across the path) error of each frame's step, RMS; as random walks per root")
    print("second and per root metre at the stretch's mean speed; the last pose's error as a share of the path and")
    print(f"in yaw. EuRoC: the gyro turned at most {1e3 * turned:.1f} mrad about its mean over the frames (standing")
    print("still), so its odometry's motion is all error.\n")
    bench.table("odometry", rows, COLUMNS)
    if kitti["outside the simulated seeds"]:
        print(f"! KITTI real outside the simulated seeds' range: {kitti['outside the simulated seeds']}\n")
    if estimate is None:
        noise = "none (too few track views)"
    else:
        noise = f"{1e3 * estimate[0]:.2f} mrad, {1e2 * estimate[1]:.2f} cm"
        noise += " (no growth beyond the stereo noise resolved: the stated floors hold)" if max(estimate) == 0 else ""
    print(f"Online estimate after the real KITTI frames (per root second): {noise}")
    print(f"EuRoC gyro: largest turn about its mean rate {1e3 * turned:.2f} mrad (standing if under {STILL_RAD})\n")
    bench.table("seeds", simulated, COLUMNS)
    bench.finish(
        {"kitti": kitti, "simulated": simulated, "euroc": euroc, "euroc_gyro_turn_rad": turned,
         "online_estimate": estimate, "stated": stated_row}
    )  # fmt: skip


if __name__ == "__main__":
    main()
