"""Speed of the evaluation code on long sequences (a wall-time budget is a benchmark, not a test).

true_revisits (which frames truly revisit a place, for loop recall) over a random walk of 5,000 frames (--quick:
2,000), median of 5 runs. Budget: under 1 s for 5,000 frames.

    python -m benchmarks.evaluation [--quick] [--out FILE]
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from benchmarks import harness
from neoslam.evaluation import LoopCriteria, true_revisits

FRAMES, QUICK_FRAMES = 5000, 2000
REPEATS = 5
BUDGET_S = 1.0


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


QUICK = f"a random walk of {QUICK_FRAMES} frames"


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, argv=argv)
    args = run.args
    rows = [time_true_revisits(QUICK_FRAMES if args.quick else FRAMES)]
    run.table("speed", rows, ["function", "frames", "revisits", "median_s", "within_budget"])
    run.finish({"rows": rows})


if __name__ == "__main__":
    main()
