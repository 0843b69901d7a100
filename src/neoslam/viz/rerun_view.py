"""A live view of a run in Rerun (the optional extra `pip install "neoslam[viewer]"`).

`neoslam run ... --rerun` spawns the viewer, `--rerun FILE.rrd` records to a file. The view is a step observer
(`pipeline.run(on_step=...)`): NeoSLAM's step is the same with or without it. Timelines: `frame` (the frame
index) and `time` (the frame's timestamp). Entities:

```
camera/image              the left image (JPEG-compressed in the recording), image sequences only
camera/detections         boxes and labels of the objects placed this frame
world/robot               the corrected pose: position and heading
world/trajectory/odometry, world/trajectory/corrected    the two trajectories (corrected: the current map)
world/objects             the object map, coloured by class, following the corrected map
world/keyframes           keyframe positions in the corrected map
world/loop_closures       a segment per accepted closure (stored frame to query frame)
cells/head_direction      the head-direction ring's activity
cells/grid_slice          the grid cells' activity in the (x, y) layer through the peak
metrics/*                 objects, keyframes, loop closures, experiences, observations this frame, frame time
world/route, world/waypoint, guidance/*   with a goal (`--goal`): the route, the next waypoint labelled with the
                          guidance's state, its state as text when it changes, distance and bearing to the waypoint
                          and distance left as scalars
```

The whole-map layers (trajectories, objects, keyframes, closures) change only a little per frame but cost their
full size each time they are logged, so they are logged when the map changes (a keyframe, a closure) and every
`MAP_EVERY_FRAMES` frames otherwise: a long run's recording then stays small.

A viewer never costs a run. The step observer copies what a frame shows (numbers, a few arrays) and hands it to a
`RerunSink`, whose worker thread alone calls the Rerun SDK (see neoslam.viz.rerun_sink for why). A live viewer that
falls behind misses frames; a recording to a file gets every frame. A viewer or file that goes away mid-run is
dropped with one warning and the run goes on; without a display, a bare `--rerun` is refused before the run.
"""

from __future__ import annotations

import sys
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.errors import ConfigError, NeoSLAMError, OutputError
from neoslam.io.atomic import atomic_file
from neoslam.viz.rerun_sink import RerunSink, SinkStartError
from neoslam.viz.rerun_target import (
    SPAWN,
    check_rerun_target,
    has_display,
    import_rerun,
    recording_target,
    start_viewer,
    viewer_url,
)

__all__ = [
    "SPAWN",
    "RerunView",
    "import_rerun",
    "check_rerun_target",
    "has_display",
    "recording_target",
    "rerun_session",
    "stderr_warning",
]

APPLICATION_ID = "neoslam"
MAP_EVERY_FRAMES = 10
JPEG_QUALITY = 80  # a grey KITTI frame: ~450 kB raw, ~40 kB as JPEG
HEADING_ARROW_M = 3.0
# Stamps after 2001 are wall-clock times (a recorded bag); earlier ones count from the start of a sequence.
EPOCH_STAMP_S = 1e9
CLASS_COLOURS = {"car": (66, 133, 244), "truck": (251, 140, 0), "bicycle": (67, 160, 71), "person": (229, 57, 53)}
OTHER_COLOUR = (158, 158, 158)
ROUTE_COLOUR = (0, 188, 212)
ROUTE_WIDTH_M = 0.5


def stderr_warning(line: str) -> None:
    """`neoslam: warning: LINE` on stderr, on a line of its own above an open progress bar."""
    from tqdm import tqdm

    tqdm.write(f"neoslam: warning: {line}", file=sys.stderr)


def _colours(labels: Sequence[str]) -> np.ndarray:
    return np.array([CLASS_COLOURS.get(label, OTHER_COLOUR) for label in labels], dtype=np.uint8).reshape(-1, 3)


@dataclass(frozen=True)
class _MapView:
    """The whole-map layers at one moment, copied out of NeoSLAM's state (which the next step changes)."""

    odometry: np.ndarray  # (n, 3)
    corrected: np.ndarray  # (n, 3)
    object_positions: np.ndarray  # (m, 3)
    object_labels: list[str]
    object_texts: list[str]
    keyframes: np.ndarray  # (k, 3)
    closures: np.ndarray  # (c, 2, 3)


@dataclass(frozen=True)
class _GuidanceView:
    """A frame's guidance to a goal: its state, the route when it is new (or the map is logged), the waypoint."""

    state: str
    changed: bool  # the state differs from the previous frame's
    route: np.ndarray | None  # (m, 3)
    waypoint: np.ndarray | None  # (3,)
    values: dict[str, float]


@dataclass(frozen=True)
class _FrameView:
    """What one frame shows, copied on the run's thread and logged on the sink's."""

    index: int
    timestamp: float
    image: np.ndarray | None
    boxes: np.ndarray  # (d, 4) XYXY
    box_labels: list[str]
    box_texts: list[str]
    position: np.ndarray
    heading: np.ndarray
    map: _MapView | None
    head_direction: np.ndarray
    grid_slice: np.ndarray
    metrics: dict[str, float]
    guidance: _GuidanceView | None = None


class RerunView:
    """Logs each step of a run to a Rerun recording; call it as `on_step(slam, frame, pose)` from the thread that
    drives the run. It copies what the frame shows and hands it to `sink` (see `rerun_session`)."""

    def __init__(self, sink: RerunSink, left_image: Callable[[int], np.ndarray] | None = None) -> None:
        self.rr = import_rerun()
        self.sink = sink
        self.left_image = left_image
        self._stamps: list[float] = []
        self._odometry: list[np.ndarray] = []
        self._keyframes = 0
        self._closures = 0
        self._last_call: float | None = None
        self._last_frame: tuple[int, float] | None = None
        self._unlogged_map: Any = None  # the NeoSLAM whose map changed since the map layers were last logged
        self.guidance: Any = None  # a GoalGuidance (neoslam.navigation.session) to show, once `follow` is given one
        self._route_shown: Any = None
        self._state_shown: str | None = None

    def follow(self, guidance: Any) -> None:
        """Show a goal's guidance too: its record of the frame must be made before the view is called."""
        self.guidance = guidance

    def __call__(self, slam: Any, frame: Any, pose: np.ndarray) -> None:
        if self.sink.lost:
            return  # a viewer that went away costs the rest of the run nothing
        self._stamps.append(frame.timestamp)
        self._odometry.append(frame.odometry_pose)
        self._last_frame = (frame.index, frame.timestamp)
        now = time.perf_counter()
        # the whole frame: reading, perception, the step and this view
        frame_ms = None if self._last_call is None else (now - self._last_call) * 1e3
        self._last_call = now
        if not self.sink.ready(frame.index):  # a live viewer behind: skip; the next map shows the changes
            self._unlogged_map = slam
            return
        keyframes, closures = len(slam.loop_detector.index.keyframes), len(slam.loop_closures)
        map_due = keyframes != self._keyframes or closures != self._closures or frame.index % MAP_EVERY_FRAMES == 0
        view = self._frame_view(slam, frame, pose, self._map_view(slam) if map_due else None, frame_ms)
        if not self.sink.submit(frame.index, partial(_log_frame, self.rr, view)):
            self._unlogged_map = slam
            return
        if view.guidance is not None:
            self._route_shown = self.guidance.route if view.guidance.route is not None else self._route_shown
            self._state_shown = view.guidance.state
        if map_due:
            self._keyframes, self._closures = keyframes, closures
            self._unlogged_map = None
        else:
            self._unlogged_map = slam

    def finish(self) -> None:
        """After the last frame: its map, if it was not logged then, so that the recording ends with the final map."""
        if self._unlogged_map is None or self._last_frame is None or self.sink.lost:
            return
        index, stamp = self._last_frame
        view = self._map_view(self._unlogged_map)
        self.sink.submit(index, partial(_log_final_map, self.rr, index, stamp, view), wait=True)
        self._unlogged_map = None

    def _frame_view(
        self, slam: Any, frame: Any, pose: np.ndarray, map_view: _MapView | None, frame_ms: float | None
    ) -> _FrameView:
        observations = frame.observations
        values: dict[str, float] = {
            "objects": len(slam.object_map.objects()),
            "keyframes": len(slam.loop_detector.index.keyframes),
            "loop_closures": len(slam.loop_closures),
            "experiences": len(slam.experience_map.experiences),
            "observations": len(observations),
        }
        if frame_ms is not None:
            values["frame_ms"] = frame_ms
        grid = np.asarray(slam.grid_cells.activity)
        return _FrameView(
            index=frame.index,
            timestamp=frame.timestamp,
            image=self.left_image(frame.index) if self.left_image is not None else None,
            boxes=np.array([o.box_left for o in observations], dtype=np.float64).reshape(-1, 4),
            box_labels=[o.label for o in observations],
            box_texts=[f"{o.label} {o.score:.2f}" for o in observations],
            position=np.array(pose[:3, 3]),
            heading=pose[:3, 0] * HEADING_ARROW_M,
            map=map_view,
            head_direction=np.array(slam.head_direction.activity),  # a copy, of the same dtype
            grid_slice=np.array(grid[:, :, slam.grid_cells.peak[2]]),
            metrics=values,
            guidance=self._guidance_view(map_view is not None),
        )

    def _guidance_view(self, map_due: bool) -> _GuidanceView | None:
        record = self.guidance.latest if self.guidance is not None else None
        if record is None:
            return None
        route = self.guidance.route
        shown = route is not None and (route is not self._route_shown or map_due)
        guidance = record.guidance
        values = {}
        if guidance is not None and guidance.distance_m is not None:
            values = {"distance_m": guidance.distance_m, "bearing_deg": float(np.degrees(guidance.bearing_rad))}
            values["remaining_m"] = guidance.remaining_m
        return _GuidanceView(
            state=record.state,
            changed=record.state != self._state_shown,
            route=np.array(route.positions) if shown else None,
            waypoint=None if guidance is None or guidance.waypoint_position is None else guidance.waypoint_position,
            values=values,
        )

    def _map_view(self, slam: Any) -> _MapView:
        """Trajectories, objects, keyframes and closures in the current (corrected) map, as copies."""
        experience_map = slam.experience_map
        odometry = np.array(self._odometry)
        corrected = np.array(experience_map.trajectory(np.array(self._stamps), odometry).positions)
        objects = slam.object_map.objects(experience_map.graph.poses)
        # A keyframe's experience was made where it was (corrected): this holds for a stored map's keyframes too.
        place = {k: experience_map.graph.poses[e][:3, 3] for k, e in experience_map.keyframe_experiences.items()}
        centres = [place[k.id] for k in slam.loop_detector.index.keyframes]
        segments = [[place[c.match_keyframe], corrected[c.query_frame]] for c in slam.loop_closures]
        return _MapView(
            odometry=odometry[:, :3, 3],
            corrected=corrected,
            object_positions=np.array([o.position for o in objects]).reshape(-1, 3),
            object_labels=[o.label for o in objects],
            object_texts=[f"{o.label} {o.id}" for o in objects],
            keyframes=np.array(centres).reshape(-1, 3),
            closures=np.array(segments).reshape(-1, 2, 3),
        )


# ------------------------------------------------------------------------------ logging, on the sink's thread


def _set_time(recording: Any, index: int, stamp: float) -> None:
    recording.set_time("frame", sequence=index)
    if stamp >= EPOCH_STAMP_S:
        recording.set_time("time", timestamp=stamp)
    else:
        recording.set_time("time", duration=stamp)


def _log_frame(rr: Any, view: _FrameView, recording: Any) -> None:
    _set_time(recording, view.index, view.timestamp)
    log = recording.log
    if view.image is not None:
        log("camera/image", rr.Image(view.image).compress(jpeg_quality=JPEG_QUALITY))
    boxes = rr.Boxes2D(
        array=view.boxes, array_format=rr.Box2DFormat.XYXY, labels=view.box_texts, colors=_colours(view.box_labels)
    )
    log("camera/detections", boxes)
    log("world/robot", rr.Arrows3D(origins=[view.position], vectors=[view.heading], colors=[(255, 255, 255)]))
    if view.map is not None:
        _log_map(rr, view.map, recording)
    log("cells/head_direction", rr.BarChart(view.head_direction))
    log("cells/grid_slice", rr.Tensor(view.grid_slice, dim_names=["x", "y"]))
    for name, value in view.metrics.items():
        log(f"metrics/{name}", rr.Scalars(float(value)))
    if view.guidance is not None:
        _log_guidance(rr, view.guidance, recording)


def _log_guidance(rr: Any, view: _GuidanceView, recording: Any) -> None:
    log = recording.log
    if view.route is not None:
        log("world/route", rr.LineStrips3D([view.route], colors=[ROUTE_COLOUR], radii=ROUTE_WIDTH_M))
    if view.waypoint is not None:
        log("world/waypoint", rr.Points3D([view.waypoint], colors=[ROUTE_COLOUR], radii=1.0, labels=[view.state]))
    if view.changed:
        log("guidance/state", rr.TextLog(view.state))
    for name, value in view.values.items():
        log(f"guidance/{name}", rr.Scalars(float(value)))


def _log_final_map(rr: Any, index: int, stamp: float, view: _MapView, recording: Any) -> None:
    _set_time(recording, index, stamp)
    _log_map(rr, view, recording)


def _log_map(rr: Any, view: _MapView, recording: Any) -> None:
    log = recording.log
    log("world/trajectory/odometry", rr.LineStrips3D([view.odometry], colors=[(200, 200, 200)]))
    log("world/trajectory/corrected", rr.LineStrips3D([view.corrected], colors=[(0, 200, 120)]))
    colours = _colours(view.object_labels)
    log("world/objects", rr.Points3D(view.object_positions, colors=colours, labels=view.object_texts, radii=0.5))
    log("world/keyframes", rr.Points3D(view.keyframes, colors=[(255, 215, 0)], radii=0.8))
    log("world/loop_closures", rr.LineStrips3D(view.closures, colors=[(255, 0, 255)]))


# ----------------------------------------------------------------------------------------------- the session


def _left_images(dataset: Any) -> Callable[[int], np.ndarray] | None:
    """Where the view gets a frame's left image: an image dataset's sequence (read again, only for the view)."""
    sequence = getattr(dataset, "sequence", None)
    if sequence is None:
        return None
    if hasattr(sequence, "left_image"):
        return sequence.left_image
    return lambda index: sequence.stereo_pair(index)[0]


class _RecordingLost(Exception):
    """A recording to a file that went away: its staging file is removed, the target never appears."""


@contextmanager
def rerun_session(
    target: str | None,
    dataset: Any = None,
    overwrite: bool = False,
    inputs: Sequence[Path | None] = (),
    warn: Callable[[str], None] = stderr_warning,
) -> Iterator[RerunView | None]:
    """The step observer of a run: None without `target`; with SPAWN a viewer is spawned (ConfigError if it does
    not start); with a path ending .rrd the recording is written there, whole or not at all. A viewer or file that
    goes away during the run is given up with one `warn(line)`; the body goes on. `dataset`: where the left images
    come from (None: no camera image)."""
    if target is None:
        yield None
        return
    check_rerun_target(target)
    if target == SPAWN:

        def viewer_lost(frame: int | None, reason: str) -> None:
            warn(f"the Rerun viewer went away{_at(frame)} ({reason}); the run goes on without it")

        def refused(reason: str) -> ConfigError:
            return ConfigError(f"--rerun: the Rerun viewer did not start ({reason}); record to a file with --rerun "
                               "FILE.rrd")  # fmt: skip

        with _viewing(_open_viewer, dataset, viewer_lost, refused, blocking=False) as view:
            yield view
        return
    path = Path(target)

    def file_lost(frame: int | None, reason: str) -> None:
        warn(f"the Rerun recording {path} failed{_at(frame)} ({reason}); the run goes on without it, {path} is "
             "not written")  # fmt: skip

    def unwritable(reason: str) -> OutputError:
        return OutputError(f"{path}: the Rerun recording could not be started ({reason})")

    with suppress(_RecordingLost), atomic_file(path, overwrite, inputs) as staging:
        with _viewing(partial(_open_file, staging), dataset, file_lost, unwritable, blocking=True) as view:
            yield view
        if view.sink.lost:
            raise _RecordingLost


def _at(frame: int | None) -> str:
    return "" if frame is None else f" at frame {frame}"


@contextmanager
def _viewing(
    open_stream: Callable[[], Any],
    dataset: Any,
    on_lost: Callable[[int | None, str], None],
    refused: Callable[[str], NeoSLAMError],
    blocking: bool,
) -> Iterator[RerunView]:
    """The view over a sink that is open and answering (else `refused(reason)` is raised, before the run); after
    the body, the final map and the sink's close."""
    sink = RerunSink(open_stream, on_lost, blocking)
    try:
        sink.start()
    except SinkStartError as error:
        raise refused(str(error)) from None
    view = RerunView(sink, _left_images(dataset))
    try:
        yield view
    except BaseException:
        sink.abort()
        raise
    view.finish()
    sink.close()


def _open_viewer() -> Any:
    """A recording stream sent to a viewer started for it (or to one already listening on Rerun's port)."""
    rr = import_rerun()
    start_viewer()
    recording = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
    recording.connect_grpc(viewer_url())
    recording.log("world", rr.ViewCoordinates.FLU, static=True)  # REP-103, as NeoSLAM's robot frame
    return recording


def _open_file(path: Path) -> Any:
    rr = import_rerun()
    recording = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4())
    recording.save(path)
    recording.log("world", rr.ViewCoordinates.FLU, static=True)
    return recording
