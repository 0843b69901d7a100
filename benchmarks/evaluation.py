"""Speed and memory of the evaluation code on long sequences (a wall-time budget is a benchmark, not a test).

true_revisits (which frames truly revisit a place, for loop recall) over a random walk of 5,000 frames (--quick:
2,000), median of 5 runs. Budget: under 1 s for 5,000 frames.

`neoslam evaluate` on an estimate and a ground truth of 1,000,000 lines each (--lines; --quick: 100,000), in TUM and
KITTI format, each run in a process of its own: wall time and peak memory (the process's maximum resident set), and
the peak above that of the same command on a 10-line pair, per line of the two files, against the figure `evaluate`
refuses work by before it reads (neoslam.commands.evaluate.BYTES_PER_LINE, with the memory budget
NEOSLAM_MAX_MEMORY).

    python -m benchmarks.evaluation [--quick] [--lines N] [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from neoslam.commands.evaluate import BYTES_PER_LINE
from neoslam.evaluation import LoopCriteria, true_revisits

FRAMES, QUICK_FRAMES = 5000, 2000
REPEATS = 5
BUDGET_S = 1.0
LINES, QUICK_LINES = 1_000_000, 100_000
BASE_LINES = 10  # the pair whose peak is the command's own
FRAME_PERIOD_S = 0.1
STEP_M = 1.0  # a drive along x, a metre a frame, the estimate 1 % long and 1 cm off
# Lines as short as their values allow (the zeros and ones of the rotation without decimals): the files of the
# longest runs stay under the 256 MiB a trajectory file may hold.
TUM_FORMAT = ["%.1f", "%.2f", "%.3f", "%d", "%d", "%d", "%d", "%d"]
KITTI_FORMAT = ["%d", "%d", "%d", "%.3f", "%d", "%d", "%d", "%d", "%d", "%d", "%d", "%.2f"]


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--lines", type=int, default=None, help=f"lines of each file (default {LINES:,})")


def time_true_revisits(frames: int) -> dict:
    rng = np.random.default_rng(4)
    positions = np.cumsum(rng.normal(0, 1.0, (frames, 3)) * [1, 1, 0], axis=0)
    times = []
    for _ in range(REPEATS):
        start = time.perf_counter()
        revisits = true_revisits(positions, LoopCriteria())
        times.append(time.perf_counter() - start)
    median = statistics.median(times)
    return {
        "function": "true_revisits",
        "frames": frames,
        "revisits": int(revisits.sum()),
        "median_s": median,
        "within_budget": median < BUDGET_S * frames / FRAMES,
    }


def _write_pair(folder: Path, form: str, lines: int) -> tuple[Path, Path]:
    """An estimate and a ground truth of `lines` poses each in `form` (tum or kitti), written a block at a time."""
    paths = folder / f"estimate_{form}_{lines}.txt", folder / f"truth_{form}_{lines}.txt"
    for path, scale, offset in ((paths[0], 1.01, 0.01), (paths[1], 1.0, 0.0)):
        with path.open("w") as handle:
            for start in range(0, lines, 100_000):
                k = np.arange(start, min(lines, start + 100_000))
                x, y = k * STEP_M * scale, np.sin(k * 1e-3) + offset
                if form == "tum":
                    rows = np.column_stack([k * FRAME_PERIOD_S, x, y, 0 * k, 0 * k, 0 * k, 0 * k, 1 + 0 * k])
                    np.savetxt(handle, rows, fmt=TUM_FORMAT)
                else:  # camera poses: the camera's z is the robot's x, its -x the robot's y
                    one, zero = np.ones_like(x), np.zeros_like(x)
                    rows = np.column_stack([one, zero, zero, -y, zero, one, zero, zero, zero, zero, one, x])
                    np.savetxt(handle, rows, fmt=KITTI_FORMAT)
    return paths


def _peak(paths: tuple[Path, Path]) -> tuple[float, float]:
    """Wall seconds and peak resident MiB of `neoslam evaluate` on the pair, in a process of its own."""
    command = [sys.executable, "-m", "neoslam", "evaluate", str(paths[0]), str(paths[1])]
    environment = os.environ | {"NEOSLAM_MAX_MEMORY": "1T"}  # measured, not refused
    started = time.perf_counter()
    with tempfile.TemporaryFile() as errors:
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=errors, env=environment)
        _, status, usage = os.wait4(process.pid, 0)  # this child's own peak, not the largest of all children
        wall = time.perf_counter() - started
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode:
            errors.seek(0)
            raise SystemExit(f"neoslam evaluate failed: {errors.read().decode(errors='replace').strip()}")
    return wall, usage.ru_maxrss / 1024  # KiB on Linux


def evaluate_memory(lines: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for form in ("tum", "kitti"):
            _, base = _peak(_write_pair(Path(folder), form, BASE_LINES))
            wall, peak = _peak(_write_pair(Path(folder), form, lines))
            per_line = (peak - base) * 2**20 / (2 * lines)
            rows.append(
                {
                    "format": form,
                    "lines_each": lines,
                    "wall_s": wall,
                    "peak_mib": peak,
                    "command_mib": base,
                    "bytes_per_line": per_line,
                    "refusal_bytes_per_line": BYTES_PER_LINE,
                    "within": per_line <= BYTES_PER_LINE,
                }
            )
    return rows


QUICK = f"a random walk of {QUICK_FRAMES} frames; trajectories of {QUICK_LINES:,} lines"
MEMORY_COLUMNS = [
    "format",
    "lines_each",
    "wall_s",
    "peak_mib",
    "command_mib",
    "bytes_per_line",
    "refusal_bytes_per_line",
    "within",
]


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv=argv)
    args = run.args
    rows = [time_true_revisits(QUICK_FRAMES if args.quick else FRAMES)]
    run.table("speed", rows, ["function", "frames", "revisits", "median_s", "within_budget"])
    lines = args.lines or (QUICK_LINES if args.quick else LINES)
    memory = evaluate_memory(lines)
    run.table("memory", memory, MEMORY_COLUMNS)
    run.finish({"rows": rows, "memory": memory})


if __name__ == "__main__":
    main()
