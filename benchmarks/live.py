"""The live node over ROS 2 (DDS on this machine): real frames played as a stereo camera driver plays them, at 10 Hz
and as fast as the player can send them, and the highest rate the node keeps up with.

Each session starts a fresh node process (`neoslam ros2`); this process plays the frames (sensor_msgs/Image and
CameraInfo, as `neoslam ros2-play` does) and listens to the node's /neoslam/odometry. Per session: frames played and
mapped, pairs dropped (the node was busy: it maps the newest pair), the node's latency from a complete pair at its
receiver to the published pose (median, 95th percentile; from its metrics.json), the same from the player's write to
this process's receipt of the pose (end to end, through DDS both ways), the latency of the first and the last ten
frames mapped (a queue would make the second grow), and the node's CPU use (its process time over its wall time,
on a 2-core machine that also runs the player).

Sequences: kitti_06_51 (51 real frames) and the real revisit the tests build (kitti_06_51 forward, back and forward
again through a photometric change: 151 frames); kitti_06_51 at 10 Hz also with `live.detect_ahead` on (the next
pair detected while the current one is mapped), for the ratio. The per-stage times (detection, and the sum of
detection, stereo and odometry) are the node's own. The rate sweep plays kitti_06_51 at rising rates; the
sustainable rate is the highest below which no rate dropped a pair after the first second (the detector's warm-up
falls there).

    python -m benchmarks.live [--quick] [--rates 8 10 12 14 16 18 20] [--repeats 1]

Speed figures of a loaded machine are worth little: the stamp records the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import harness
from benchmarks.harness import data_root
from benchmarks.real_streets import THIRD_PASS

QUICK = "kitti_06_51 at 10 Hz only"
RATES = [3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0]
TARGET_HZ = 10.0
WARM_UP_S = 1.0  # stamps within this of the first are the detector's warm-up: drops there are not counted
START_TIMEOUT_S = 180
IDLE_EXIT_S = 3
ENDS = 10  # frames at each end of a session whose latencies are compared (a growing queue shows there)
LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "</General></Domain></CycloneDDS>"
)
DOMAIN = 231  # a domain of its own: nothing else on the machine hears the benchmark


def arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rates", type=float, nargs="+", default=RATES, help="rates of the sweep, Hz")
    parser.add_argument("--repeats", type=int, default=1, help="sessions per sequence and rate")


def _sequences() -> dict[str, Any]:
    from neoslam.datasets.kitti import read_kitti_sequence
    from neoslam.datasets.replay import forward_back_forward

    base = read_kitti_sequence(data_root() / "kitti_06_51", "06")
    return {"kitti_06_51": base, "revisit": forward_back_forward(base, THIRD_PASS)}


class _PoseListener:
    """This process's subscription to the node's corrected pose: when each stamp's pose arrived."""

    def __init__(self, domain: Any) -> None:
        from neoslam.live.messages import Odometry
        from neoslam.live.transport import state_qos

        self.arrived: dict[int, float] = {}
        self._reader = domain.reader("/neoslam/odometry", Odometry, state_qos(100))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._listen, daemon=True)
        self._thread.start()

    def _listen(self) -> None:
        from neoslam.live.conversions import stamp_ns
        from neoslam.live.transport import taken

        while not self._stop.is_set():
            for sample in taken(self._reader, 100):
                self.arrived.setdefault(stamp_ns(sample.header), time.monotonic())
            time.sleep(0.001)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=1)


def _session(sequence: Any, rate_hz: float | None, folder: Path, detect_ahead: bool = False) -> dict[str, Any]:
    """One node process mapping one played sequence (`detect_ahead`: live.detect_ahead)."""
    from neoslam.config.live import LiveConfig
    from neoslam.live.player import play_sequence
    from neoslam.live.transport import Ros2Domain

    environment = {**os.environ, "CYCLONEDDS_URI": os.environ.get("CYCLONEDDS_URI", LOOPBACK)}
    environment["NEOSLAM_LIVE__DETECT_AHEAD"] = str(detect_ahead).lower()
    os.environ["CYCLONEDDS_URI"] = environment["CYCLONEDDS_URI"]
    results = folder / "node"
    command = [sys.executable, "-m", "neoslam", "ros2", "--out", str(results), "--domain-id", str(DOMAIN)]
    node = subprocess.Popen(
        [*command, "--idle-exit", str(IDLE_EXIT_S)], env=environment, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    domain = Ros2Domain(DOMAIN)
    try:
        listener = _PoseListener(domain)
        report = play_sequence(sequence, domain, LiveConfig(), threading.Event(), rate_hz, False, START_TIMEOUT_S)
        _, err = node.communicate(timeout=START_TIMEOUT_S)
        time.sleep(0.2)
        listener.close()
    finally:
        if node.poll() is None:
            node.kill()
        domain.close()
    if node.returncode != 0:
        raise SystemExit(f"benchmark: the node failed: {err.decode(errors='replace')}")
    metrics = json.loads((results / "metrics.json").read_text())
    return _figures(report, listener.arrived, metrics)


def _figures(report: Any, arrived: dict[int, float], metrics: dict[str, Any]) -> dict[str, Any]:
    live = metrics["live"]
    sent = dict(zip(report.stamps_ns, report.sent_s, strict=True))
    mapped = sorted(stamp for stamp in arrived if stamp in sent)
    end_to_end = np.array([arrived[s] - sent[s] for s in mapped]) * 1e3
    first = report.stamps_ns[0] if report.stamps_ns else 0
    after_warm_up = [s for s in report.stamps_ns if s - first > WARM_UP_S * 1e9]
    missed_after = len([s for s in after_warm_up if s not in arrived])
    played_s = report.sent_s[-1] - report.sent_s[0] if len(report.sent_s) > 1 else 0.0
    row = {
        "played": report.frames,
        "played_hz": round((report.frames - 1) / played_s, 1) if played_s > 0 else None,
        "mapped": live["frames"],
        "dropped": live["pairs_dropped"],
        "dropped_after_1s": missed_after,
        "latency_ms_median": live.get("latency_ms_median"),
        "latency_ms_p95": live.get("latency_ms_p95"),
        "end_to_end_ms_median": round(float(np.median(end_to_end)), 1) if len(end_to_end) else None,
        "end_to_end_ms_p95": round(float(np.percentile(end_to_end, 95)), 1) if len(end_to_end) else None,
        "first_10_ms": round(float(np.median(end_to_end[:ENDS])), 1) if len(end_to_end) else None,
        "last_10_ms": round(float(np.median(end_to_end[-ENDS:])), 1) if len(end_to_end) else None,
        "node_cpu_percent": live["cpu_percent"],
    }
    row |= {f"{k}": v for k, v in metrics.get("perception", {}).items() if k.endswith("_ms_median")}
    return row


def main(argv: list[str] | None = None) -> dict[str, Any]:
    run = harness.start(__name__, __doc__, QUICK, arguments, argv, data=(("kitti_06_51",),))
    sequences = _sequences()
    plan: list[tuple[str, float | None, bool]] = [("kitti_06_51", TARGET_HZ, False)]
    if not run.quick:
        plan += [("kitti_06_51", TARGET_HZ, True), ("kitti_06_51", None, False)]
        plan += [("revisit", TARGET_HZ, False), ("revisit", None, False)]
    rows = []
    with tempfile.TemporaryDirectory(prefix="neoslam-live-") as scratch:
        for repeat in range(run.args.repeats):
            for name, rate, ahead in plan:
                folder = Path(scratch) / f"{name}-{rate}-{ahead}-{repeat}"
                figures = _session(sequences[name], rate, folder, ahead)
                rate_name = "fastest" if rate is None else f"{rate:g} Hz"
                row = {"sequence": name, "rate": rate_name, "detect_ahead": "yes" if ahead else "no"}
                rows.append(row | figures)
                print(f"{name} at {rate_name}, detect ahead {row['detect_ahead']}: {figures}", file=sys.stderr)
        columns = ["sequence", "rate", "detect_ahead", "played", "played_hz", "mapped", "dropped", "latency_ms_median"]
        columns += ["latency_ms_p95", "end_to_end_ms_median", "end_to_end_ms_p95", "first_10_ms", "last_10_ms"]
        columns += ["node_cpu_percent", "detection_ms_median", "total_ms_median"]
        run.table("sessions", rows, columns, title="Sessions (latency: complete pair at the node -> pose published):")
        sweep = []
        if not run.quick:
            for rate in run.args.rates:
                folder = Path(scratch) / f"sweep-{rate}"
                sweep.append({"rate_hz": rate} | _session(sequences["kitti_06_51"], rate, folder))
            sweep_columns = ["rate_hz", "played_hz", "mapped", "dropped", "dropped_after_1s", "latency_ms_median"]
            sweep_columns += ["latency_ms_p95", "node_cpu_percent"]
            run.table("sweep", sweep, sweep_columns, title="Rate sweep on kitti_06_51:")
    sustainable = None
    for row in sorted(sweep, key=lambda row: row["rate_hz"]):
        if row["dropped_after_1s"]:
            break
        sustainable = row["rate_hz"]
    if not run.quick:
        print(f"sustainable rate: {sustainable} Hz (no pair dropped after the first second)\n")
    at_target = rows[0]
    return run.finish(
        {
            "sessions": rows,
            "sweep": sweep,
            "sustainable_hz": sustainable,
            "latency_ms_p95_at_10hz": at_target["latency_ms_p95"],
            "dropped_at_10hz": at_target["dropped"],
        }
    )


if __name__ == "__main__":
    main()
