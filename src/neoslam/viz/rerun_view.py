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
```

The whole-map layers (trajectories, objects, keyframes, closures) change only a little per frame but cost their
full size each time they are logged, so they are logged when the map changes (a keyframe, a closure) and every
`MAP_EVERY_FRAMES` frames otherwise: a long run's recording then stays small.
"""

from __future__ import annotations

import shutil
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from neoslam.errors import ConfigError
from neoslam.io.atomic import atomic_file

__all__ = ["SPAWN", "RerunView", "import_rerun", "check_rerun_target", "recording_target", "rerun_session"]

SPAWN = "spawn"  # the --rerun value that spawns the viewer instead of recording to a file
INSTALL_HINT = 'pip install "neoslam[viewer]"'
MAP_EVERY_FRAMES = 10
JPEG_QUALITY = 80  # a grey KITTI frame: ~450 kB raw, ~40 kB as JPEG
HEADING_ARROW_M = 3.0
# Stamps after 2001 are wall-clock times (a recorded bag); earlier ones count from the start of a sequence.
EPOCH_STAMP_S = 1e9
CLASS_COLOURS = {"car": (66, 133, 244), "truck": (251, 140, 0), "bicycle": (67, 160, 71), "person": (229, 57, 53)}
OTHER_COLOUR = (158, 158, 158)


def import_rerun() -> Any:
    """The rerun module, or one line saying how to install it."""
    try:
        import rerun
    except ImportError:
        raise ConfigError(f"--rerun needs the Rerun viewer, an optional extra: {INSTALL_HINT}") from None
    return rerun


VIEWER_EXECUTABLE = "rerun"  # the viewer rerun-sdk's spawn() starts, looked up on PATH


def check_rerun_target(target: str | None) -> None:
    """Before any work: the --rerun value is SPAWN or a file ending .rrd, and Rerun is installed."""
    if target is None:
        return
    if target != SPAWN and not target.endswith(".rrd"):
        raise ConfigError(f"--rerun takes no value (spawn the viewer) or a file ending .rrd, not {target!r}")
    import_rerun()
    if target == SPAWN and shutil.which(VIEWER_EXECUTABLE) is None:
        raise _viewer_missing()


def recording_target(target: str | None, out: Path, staging: Path) -> str | None:
    """Where the recording is written: a file inside the results folder goes into its staging folder (the folder
    appears whole, with the recording, when the run is done); any other target is kept."""
    if target is None or target == SPAWN:
        return target
    path, folder = Path(target).resolve(), out.resolve()
    return str(staging / path.relative_to(folder)) if folder in path.parents else target


def _colours(labels: Sequence[str]) -> np.ndarray:
    return np.array([CLASS_COLOURS.get(label, OTHER_COLOUR) for label in labels], dtype=np.uint8).reshape(-1, 3)


class RerunView:
    """Logs each step of a run to a Rerun recording; call it as `on_step(slam, frame, pose)`."""

    def __init__(self, recording: Any, left_image: Callable[[int], np.ndarray] | None = None) -> None:
        self.rr = import_rerun()
        self.recording = recording
        self.left_image = left_image
        self._stamps: list[float] = []
        self._odometry: list[np.ndarray] = []
        self._keyframes = 0
        self._closures = 0
        self._last_call: float | None = None
        self._unlogged_map: Any = None  # the NeoSLAM whose map changed since the map layers were last logged
        recording.log("world", self.rr.ViewCoordinates.FLU, static=True)  # REP-103, as NeoSLAM's robot frame

    def __call__(self, slam: Any, frame: Any, pose: np.ndarray) -> None:
        rr, log = self.rr, self.recording.log
        self.recording.set_time("frame", sequence=frame.index)
        if frame.timestamp >= EPOCH_STAMP_S:
            self.recording.set_time("time", timestamp=frame.timestamp)
        else:
            self.recording.set_time("time", duration=frame.timestamp)
        self._stamps.append(frame.timestamp)
        self._odometry.append(frame.odometry_pose)
        self._log_camera(frame)
        heading = pose[:3, 0] * HEADING_ARROW_M
        log("world/robot", rr.Arrows3D(origins=[pose[:3, 3]], vectors=[heading], colors=[(255, 255, 255)]))
        keyframes, closures = len(slam.loop_detector.index.keyframes), len(slam.loop_closures)
        if keyframes != self._keyframes or closures != self._closures or frame.index % MAP_EVERY_FRAMES == 0:
            self._log_map(slam)
            self._keyframes, self._closures = keyframes, closures
            self._unlogged_map = None
        else:
            self._unlogged_map = slam
        self._log_cells(slam)
        self._log_metrics(slam, frame)

    def finish(self) -> None:
        """After the last frame: its map, if it was not logged then, so that the recording ends with the final map."""
        if self._unlogged_map is not None:
            self._log_map(self._unlogged_map)
            self._unlogged_map = None

    def _log_camera(self, frame: Any) -> None:
        rr = self.rr
        if self.left_image is not None:
            image = rr.Image(self.left_image(frame.index)).compress(jpeg_quality=JPEG_QUALITY)
            self.recording.log("camera/image", image)
        labels = [o.label for o in frame.observations]
        boxes = np.array([o.box_left for o in frame.observations], dtype=np.float64).reshape(-1, 4)
        texts = [f"{o.label} {o.score:.2f}" for o in frame.observations]
        self.recording.log(
            "camera/detections",
            rr.Boxes2D(array=boxes, array_format=rr.Box2DFormat.XYXY, labels=texts, colors=_colours(labels)),
        )

    def _log_map(self, slam: Any) -> None:
        """Trajectories, objects, keyframes and closures in the current (corrected) map."""
        rr, log = self.rr, self.recording.log
        experience_map = slam.experience_map
        odometry = np.array(self._odometry)
        corrected = experience_map.trajectory(np.array(self._stamps), odometry).positions
        log("world/trajectory/odometry", rr.LineStrips3D([odometry[:, :3, 3]], colors=[(200, 200, 200)]))
        log("world/trajectory/corrected", rr.LineStrips3D([corrected], colors=[(0, 200, 120)]))
        objects = slam.object_map.objects(experience_map.graph.poses)
        positions = np.array([o.position for o in objects]).reshape(-1, 3)
        labels = [o.label for o in objects]
        texts = [f"{o.label} {o.id}" for o in objects]
        log("world/objects", rr.Points3D(positions, colors=_colours(labels), labels=texts, radii=0.5))
        # A keyframe's experience was made where it was (corrected): this holds for a stored map's keyframes too.
        place = {k: experience_map.graph.poses[e][:3, 3] for k, e in experience_map.keyframe_experiences.items()}
        centres = [place[k.id] for k in slam.loop_detector.index.keyframes]
        log("world/keyframes", rr.Points3D(np.array(centres).reshape(-1, 3), colors=[(255, 215, 0)], radii=0.8))
        segments = [[place[c.match_keyframe], corrected[c.query_frame]] for c in slam.loop_closures]
        log("world/loop_closures", rr.LineStrips3D(np.array(segments).reshape(-1, 2, 3), colors=[(255, 0, 255)]))

    def _log_cells(self, slam: Any) -> None:
        rr = self.rr
        self.recording.log("cells/head_direction", rr.BarChart(np.asarray(slam.head_direction.activity)))
        grid = np.asarray(slam.grid_cells.activity)
        layer = grid[:, :, slam.grid_cells.peak[2]]
        self.recording.log("cells/grid_slice", rr.Tensor(layer, dim_names=["x", "y"]))

    def _log_metrics(self, slam: Any, frame: Any) -> None:
        now = time.perf_counter()
        values = {
            "objects": len(slam.object_map.objects()),
            "keyframes": len(slam.loop_detector.index.keyframes),
            "loop_closures": len(slam.loop_closures),
            "experiences": len(slam.experience_map.experiences),
            "observations": len(frame.observations),
        }
        if self._last_call is not None:  # the whole frame: reading, perception, the step and this view
            values["frame_ms"] = (now - self._last_call) * 1e3
        self._last_call = now
        for name, value in values.items():
            self.recording.log(f"metrics/{name}", self.rr.Scalars(float(value)))


def _left_images(dataset: Any) -> Callable[[int], np.ndarray] | None:
    """Where the view gets a frame's left image: an image dataset's sequence (read again, only for the view)."""
    sequence = getattr(dataset, "sequence", None)
    if sequence is None:
        return None
    if hasattr(sequence, "left_image"):
        return sequence.left_image
    return lambda index: sequence.stereo_pair(index)[0]


@contextmanager
def rerun_session(
    target: str | None, dataset: Any, overwrite: bool = False, inputs: Sequence[Path | None] = ()
) -> Iterator[RerunView | None]:
    """The step observer of a run: None without `target`; with SPAWN a viewer is spawned; with a path ending .rrd
    the recording is written there (whole or not at all, as any output)."""
    if target is None:
        yield None
        return
    check_rerun_target(target)
    rr = import_rerun()
    recording = rr.RecordingStream("neoslam", recording_id=uuid.uuid4())
    if target == SPAWN:
        _spawn_viewer(recording)
        with _viewing(recording, dataset) as view:
            yield view
        return
    with atomic_file(Path(target), overwrite, inputs) as staging:
        recording.save(staging)
        try:
            with _viewing(recording, dataset) as view:
                yield view
        finally:
            recording.disconnect()


def _spawn_viewer(recording: Any) -> None:
    """Start the Rerun viewer; one line saying how to get it when its executable is not on PATH."""
    try:
        recording.spawn()
    except RuntimeError as error:
        if "executable" not in str(error):
            raise
        raise _viewer_missing() from None


def _viewer_missing() -> ConfigError:
    return ConfigError(
        f"--rerun: the Rerun viewer (`{VIEWER_EXECUTABLE}`) is not on PATH; the viewer extra installs it into the "
        'environment (pip install "neoslam[viewer]", then run with that environment\'s bin folder on PATH), or '
        "record to a file with --rerun FILE.rrd"
    )


@contextmanager
def _viewing(recording: Any, dataset: Any) -> Iterator[RerunView]:
    """The view over a recording stream; everything logged is flushed however the run ends."""
    try:
        view = RerunView(recording, _left_images(dataset))
        yield view
        view.finish()
    finally:
        recording.flush()
