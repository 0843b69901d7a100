"""`neoslam ros2` (the live node), `neoslam ros2-play` (a recorded sequence played as a stereo camera driver) and
`neoslam ros2-record` (topics into a ROS 2 bag): ROS 2 over Cyclone DDS, the optional extra `ros2`."""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from pathlib import Path
from typing import Any

from neoslam import stopping
from neoslam.commands.run import observers, write_results
from neoslam.commands.run_metrics import run_metrics
from neoslam.config import NeoSLAMConfig
from neoslam.datasets.opening import ImageInputs, open_stereo_sequence
from neoslam.errors import ConfigError
from neoslam.io.atomic import atomic_directory, check_target
from neoslam.io.route_files import write_guidance_csv
from neoslam.store.recording import check_map_path, map_recording
from neoslam.viz.rerun_view import check_rerun_target, recording_target, rerun_session

__all__ = ["INSTALL_HINT", "domain_id", "run_node", "play", "record", "live_metrics"]

INSTALL_HINT = 'pip install "neoslam[ros2]"'
DOMAIN_ENV = "ROS_DOMAIN_ID"
# DDS maps a domain id to UDP ports; ids above 232 give ports beyond 65535 (ROS 2 recommends 0-101)
MAX_DOMAIN_ID = 232


def _import_live() -> None:
    """One line naming the extra when Cyclone DDS is not installed."""
    try:
        import cyclonedds  # noqa: F401
    except ImportError:
        raise ConfigError(f"the ROS 2 commands need Eclipse Cyclone DDS, an optional extra: {INSTALL_HINT}") from None


def domain_id(given: int | None) -> int:
    """The ROS 2 domain: `--domain-id`, else ROS_DOMAIN_ID, else 0 (as every ROS 2 node chooses it)."""
    if given is None:
        text = os.environ.get(DOMAIN_ENV, "").strip()
        if not text:
            return 0
        if not text.isdigit():
            raise ConfigError(f"{DOMAIN_ENV}={text!r} is not a domain id (an integer 0-{MAX_DOMAIN_ID})")
        given = int(text)
    if not 0 <= given <= MAX_DOMAIN_ID:
        raise ConfigError(f"ROS domain id {given} is out of range (0-{MAX_DOMAIN_ID})")
    return given


def live_metrics(live_run: Any, config: NeoSLAMConfig, session_name: str) -> dict[str, Any]:
    """metrics.json of a live session: the run's figures and how the node kept up (`live`)."""
    from neoslam.live.node import LiveSource
    from neoslam.live.reporting import latency_figures

    source = LiveSource(session_name, len(live_run.stamps_ns))
    metrics = run_metrics(source, live_run.result, config, live_run.wall_s)
    counters = live_run.counters
    metrics["live"] = {
        "stopped_by": live_run.stopped_by,
        "frames": len(live_run.stamps_ns),
        "pairs_received": counters.pairs,
        "pairs_dropped": counters.dropped,
        "images_unpaired": counters.unpaired,
        "pairs_out_of_order": counters.out_of_order,
        "pairs_skipped": live_run.skipped,
        "cpu_percent": round(100 * live_run.cpu_s / max(live_run.wall_s, 1e-9), 1),
        **latency_figures(live_run.latencies_s),
    }
    if live_run.perception:
        metrics["perception"] = live_run.perception
    return metrics


def run_node(
    config: NeoSLAMConfig,
    domain: int,
    out: Path | None = None,
    overwrite: bool = False,
    read: Sequence[Path | None] = (),
    map_path: Path | None = None,
    localise_only: bool = False,
    max_frames: int | None = None,
    idle_exit_s: float | None = None,
    warn: Callable[[str], None] = print,
    inform: Callable[[str], None] | None = None,
    goal: str | None = None,
    stale_goal: bool = False,
    rerun: str | None = None,
) -> dict[str, Any]:
    """Run the live node until Ctrl-C or SIGTERM (or `max_frames`, or `idle_exit_s` without images), then commit
    the map and write the results folder `out` (if given). `goal`: guide to it (see `neoslam run --goal`).
    `rerun`: show the session in Rerun (see `neoslam run --rerun`). Returns the session's metrics."""
    _import_live()
    from neoslam.live.node import LiveNode
    from neoslam.navigation.session import GoalGuidance

    guidance = GoalGuidance(goal, config, stale_goal) if goal is not None else None

    check_rerun_target(rerun)
    if out is not None:
        check_target(out, overwrite, list(read))
    if map_path is not None:
        check_map_path(map_path, out, read, localise_only)
    elif localise_only:
        raise ConfigError("--localise-only needs --map FILE")
    session_name = f"ros2{config.live.left_topic}"
    stop = threading.Event()
    with stopping.graceful(stop, config.live.stop_grace_s) as state, ExitStack() as stack:
        staging = stack.enter_context(atomic_directory(out, overwrite, list(read))) if out is not None else None
        session = stack.enter_context(map_recording(map_path, config, localise_only)) if map_path else None
        stored = session.stored if session is not None else None
        recorder = session.recorder if session is not None else None
        view = stack.enter_context(rerun_session(_rerun_target(rerun, out, staging), None, overwrite, list(read)))
        if view is not None and guidance is not None:
            view.follow(guidance)
        finish = recorder.finish if recorder is not None else None
        on_step = observers(recorder, view)
        node = LiveNode(config, domain, stored, session_name, on_step, warn, inform, finish, guidance)
        live_run = node.run(stop, max_frames, idle_exit_s)
        metrics = live_metrics(live_run, config, session_name)
        if state.signum is not None:
            metrics["live"]["stopped_by"] = signal.Signals(state.signum).name
        if guidance is not None:
            metrics["guidance"] = guidance.summary()
        if staging is not None:
            if guidance is not None:
                write_guidance_csv(staging / "guidance.csv", guidance.records)
            # no plots: they take seconds, and a stopped node has less than one to write its results
            write_results(staging, _Named(session_name, live_run), live_run.result, config, metrics, session, False)
    return metrics


def _rerun_target(rerun: str | None, out: Path | None, staging: Path | None) -> str | None:
    """Where the view goes: a recording inside the results folder is written into its staging folder."""
    if out is None or staging is None:
        return rerun
    return recording_target(rerun, out, staging)


class _Named:
    """The live session as `write_results` reads a dataset: a name, no ground truth."""

    def __init__(self, name: str, live_run: Any) -> None:
        self.name = name
        self.ground_truth = None
        self._frames = len(live_run.stamps_ns)

    def __len__(self) -> int:
        return self._frames


def play(
    data: Path,
    config: NeoSLAMConfig,
    domain: int,
    inputs: ImageInputs = ImageInputs(),
    rate_hz: float | None = None,
    compressed: bool = False,
    wait_s: float = 0.0,
    frames: str | None = None,
) -> Any:
    """Play a recorded stereo sequence (or the frames START:STOP of it) on the configured camera topics; stops
    early on Ctrl-C or SIGTERM."""
    _import_live()
    from neoslam.live.player import play_sequence
    from neoslam.live.transport import Ros2Domain

    if rate_hz is not None and not rate_hz > 0:
        raise ConfigError(f"--rate must be positive, not {rate_hz:g}")
    sequence = open_stereo_sequence(data, config, inputs)
    chosen = _frame_range(frames, len(sequence))
    stop = threading.Event()
    with stopping.graceful(stop, config.live.stop_grace_s):
        ros = Ros2Domain(domain)
        try:
            return play_sequence(sequence, ros, config.live, stop, rate_hz, compressed, wait_s, chosen)
        finally:
            ros.close()


def _frame_range(text: str | None, count: int) -> range | None:
    """START:STOP (either may be left out) as the frames of a sequence of `count`; one line when malformed."""
    if text is None:
        return None
    start, colon, stop = text.partition(":")
    try:
        chosen = range(count)[slice(int(start) if start else None, int(stop) if stop else None)] if colon else None
    except ValueError:
        chosen = None
    if chosen is None or len(chosen) == 0:
        raise ConfigError(f"--frames {text!r}: give START:STOP selecting at least one of the {count} frames")
    return chosen


def record(
    topics: list[str],
    bag: Path,
    domain: int,
    config: NeoSLAMConfig,
    overwrite: bool = False,
    discovery_s: float = 10.0,
    storage: str = "sqlite3",
    idle_exit_s: float | None = None,
    ready: Callable[[list[str]], None] | None = None,
) -> Any:
    """Record ROS 2 topics into a new bag folder (written whole when the recording stops, as any output);
    `ready(topics)` once recording."""
    _import_live()
    from neoslam.live.recorder import record_topics
    from neoslam.live.transport import Ros2Domain

    if not topics:
        raise ConfigError("name at least one topic to record")
    stop = threading.Event()
    with stopping.graceful(stop, config.live.stop_grace_s), atomic_directory(bag, overwrite, []) as staging:
        ros = Ros2Domain(domain)
        try:
            # rosbags writes a bag into a folder of its own that must not exist yet: one inside the staging folder
            report = record_topics(ros, topics, staging / "bag", stop, discovery_s, storage, idle_exit_s, ready)
        finally:
            ros.close()
        for path in (staging / "bag").iterdir():
            path.rename(staging / path.name)
        (staging / "bag").rmdir()
    return report
