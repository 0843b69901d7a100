"""Speed of the evaluation code on long sequences (a wall-time budget is a benchmark, not a test).

true_revisits (which frames truly revisit a place, for loop recall) over a random walk of 5,000 frames (--quick:
2,000), median of 5 runs. Budget: under 1 s for 5,000 frames (it was asserted in tests/evaluation/test_loops.py).

    python benchmarks/evaluation.py [--quick] [--json FILE]
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import markdown_table, parse_args, write_json  # noqa: E402
from neoslam.evaluation import LoopCriteria, true_revisits  # noqa: E402

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


def main() -> None:
    args = parse_args(__doc__.splitlines()[0])
    rows = [time_true_revisits(QUICK_FRAMES if args.quick else FRAMES)]
    print(markdown_table(rows, ["function", "frames", "revisits", "median_s", "within_budget"]))
    write_json(args.json, {"rows": rows})


if __name__ == "__main__":
    main()
