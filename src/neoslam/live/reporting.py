"""What the live node says about itself: its status topic, and the line it prints when no images come."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from neoslam.config.live import LiveConfig
from neoslam.live.receiver import Receiver
from neoslam.live.transport import Ros2Domain

__all__ = ["LiveStatus", "missing_images", "latency_figures"]

RECENT_FRAMES = 100  # the status's latency figures are over this many recent frames
MS_PER_S = 1e3


def latency_figures(latencies_s: list[float] | np.ndarray) -> dict[str, float]:
    """Median and 95th percentile of per-frame latencies, ms (empty without frames)."""
    values = np.asarray(latencies_s, dtype=float)
    if not len(values):
        return {}
    return {
        "latency_ms_median": round(float(np.median(values)) * MS_PER_S, 1),
        "latency_ms_p95": round(float(np.percentile(values, 95)) * MS_PER_S, 1),
    }


class LiveStatus:
    """The node's state and counters, published every `live.status_period_s` as diagnostic_msgs/DiagnosticArray."""

    def __init__(
        self, config: LiveConfig, receiver: Receiver, slam: Any, latencies_s: list[float], skipped: dict[str, int]
    ) -> None:
        self.config = config
        self.receiver = receiver
        self.slam = slam
        self.latencies_s = latencies_s
        self.skipped = skipped
        self._due = time.monotonic()
        self._cpu = (time.monotonic(), time.process_time())

    def state(self) -> tuple[str, str]:
        """(level, message): what the node is doing."""
        counters = self.receiver.counters
        if not self.latencies_s:
            if counters.pairs == 0:
                return "warn", "waiting for stereo images"
            return "warn", "waiting for CameraInfo" if self.skipped["no_camera_info"] else "starting"
        if self.slam.stored.experiences and self.slam.session.relocalised_frame is None:
            return "ok", "relocalising in the stored map"
        return "ok", "localised in the stored map" if self.slam.stored.experiences else "mapping"

    def values(self) -> dict[str, Any]:
        counters, slam = self.receiver.counters, self.slam
        now, cpu = time.monotonic(), time.process_time()
        cpu_share = (cpu - self._cpu[1]) / max(now - self._cpu[0], 1e-9)
        self._cpu = (now, cpu)
        values: dict[str, Any] = {
            "frames": len(self.latencies_s),
            "pairs_received": counters.pairs,
            "pairs_dropped": counters.dropped,
            "images_unpaired": counters.unpaired,
            "pairs_out_of_order": counters.out_of_order,
            **{f"pairs_skipped_{reason}": count for reason, count in self.skipped.items()},
            "keyframes": len(slam.keyframes.frames),
            "loop_closures": len(slam.loop_closures),
            "objects": len(slam.object_map.objects()),
            "relocalised_frame": slam.session.relocalised_frame,
            "cpu_percent": round(100 * cpu_share, 1),
        }
        return values | latency_figures(self.latencies_s[-RECENT_FRAMES:])

    def publish_when_due(self, outputs: Any, now: float, stamp: int) -> None:
        if now >= self._due:
            self.publish(outputs, stamp)

    def publish(self, outputs: Any, stamp: int, final: bool = False) -> None:
        level, message = self.state()
        if final:
            message = f"stopped: {message}"
        outputs.status(level, message, self.values(), stamp)
        self._due = time.monotonic() + self.config.status_period_s


def missing_images(waited_s: float, receiver: Receiver, domain: Ros2Domain, domain_id: int) -> str:
    """One line: what is missing after `waited_s`, the topics subscribed to and those published on the domain."""
    counters, config = receiver.counters, receiver.config
    if counters.left == 0 and counters.right == 0:
        what = "no images"
    elif counters.pairs == 0:
        slop = f"{config.pair_slop_s * MS_PER_S:g} ms"
        what = f"{counters.left} left and {counters.right} right images but no pair within {slop} (live.pair_slop_s)"
    else:
        what = f"{counters.pairs} stereo pairs but no CameraInfo on both camera_info topics"
    subscribed = ", ".join(receiver.topics.values())
    seen = ", ".join(f"{p.topic} ({p.type_name})" for p in domain.publications()) or "none"
    return (
        f"{what} after {waited_s:.0f} s; subscribed to {subscribed} on ROS domain {domain_id}; topics published "
        f"there: {seen}"
    )
