"""Reading stereo frames from ROS bags against reading them from the KITTI folder.

The 51 frames of kitti_06_51 are written as a ROS 1 bag and as ROS 2 bags (sqlite3 and mcap; mono8 Images, and
one with the right camera's PNG files as CompressedImage) with the tests' writer
(tests/datasets/bags/conftest.py). For each input: the time to open it (for a bag: index every stamp and decode the
first pair), the median time to read one stereo pair (several passes, the first a warm-up), its size, and whether
every pixel equals the KITTI folder's.

    python -m benchmarks.bag_read [--quick] [--out FILE]
"""

from __future__ import annotations

import importlib.util
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import harness
from benchmarks.harness import REPO_ROOT, data_root
from neoslam.config.perception import BagConfig
from neoslam.datasets.bag import open_bag
from neoslam.datasets.kitti import read_kitti_sequence

PASSES, QUICK_PASSES = 4, 2
BAGS = {  # name: (file or folder name, kind, right camera as CompressedImage)
    "ROS 1 .bag, Image mono8": ("kitti.bag", "ros1", False),
    "ROS 2 sqlite3, Image mono8": ("kitti_sqlite3", "sqlite3", False),
    "ROS 2 mcap, Image mono8": ("kitti_mcap", "mcap", False),
    "ROS 2 sqlite3, right CompressedImage PNG": ("kitti_png", "sqlite3", True),
}


def _bag_writer():
    """The tests' bag writer (rosbags' ROS 1 and ROS 2 writers), loaded from its file."""
    spec = importlib.util.spec_from_file_location(
        "bag_writer", REPO_ROOT / "tests" / "datasets" / "bags" / "conftest.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.write_stereo_bag


def _size_mb(path: Path) -> float:
    files = [path] if path.is_file() else [p for p in path.rglob("*") if p.is_file()]
    return sum(p.stat().st_size for p in files) / 1e6


def _read_times(sequence, passes: int) -> np.ndarray:
    times = []
    for repeat in range(passes):
        for index in range(len(sequence)):
            start = time.perf_counter()
            sequence.stereo_pair(index)
            if repeat:  # the first pass warms the caches
                times.append(time.perf_counter() - start)
    return np.array(times)


QUICK = f"{QUICK_PASSES - 1} timed pass instead of {PASSES - 1}"


def main(argv: list[str] | None = None) -> None:
    run = harness.start(__name__, __doc__, QUICK, argv=argv, data=(("kitti_06_51",),))
    args = run.args
    passes = QUICK_PASSES if args.quick else PASSES
    root = data_root() / "kitti_06_51"
    start = time.perf_counter()
    kitti = read_kitti_sequence(root, "06")
    rows = [
        {
            "input": "KITTI folder, PNG files",
            "open_ms": (time.perf_counter() - start) * 1e3,
            "pair_ms_median": float(np.median(_read_times(kitti, passes))) * 1e3,
            "size_mb": _size_mb(root / "sequences" / "06"),
            "same_pixels": "-",
        }
    ]
    write = _bag_writer()
    with tempfile.TemporaryDirectory() as folder:
        for name, (file_name, kind, compressed) in BAGS.items():
            path = write(Path(folder) / file_name, kitti, len(kitti), kind, right_compressed=compressed)
            start = time.perf_counter()
            bag = open_bag(path, BagConfig())
            open_ms = (time.perf_counter() - start) * 1e3
            same = all(
                np.array_equal(a, b)
                for i in range(len(kitti))
                for a, b in zip(bag.stereo_pair(i), kitti.stereo_pair(i), strict=True)
            )
            rows.append(
                {
                    "input": name,
                    "open_ms": open_ms,
                    "pair_ms_median": float(np.median(_read_times(bag, passes))) * 1e3,
                    "size_mb": _size_mb(path),
                    "same_pixels": "yes" if same else "NO",
                }
            )
            bag.close()
    print(f"{len(kitti)} stereo frames of kitti_06_51 (1226x370 grey), {passes - 1} timed passes\n")
    run.table("inputs", rows, ["input", "open_ms", "pair_ms_median", "size_mb", "same_pixels"])
    run.finish({"frames": len(kitti), "rows": rows})


if __name__ == "__main__":
    main()
