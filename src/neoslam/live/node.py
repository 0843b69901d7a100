"""The live node: stereo pairs from ROS 2 topics through the perception front end and NeoSLAM, the corrected pose
published for every frame and the map whenever it changes.

The loop takes the newest pair the receiver holds (neoslam.live.receiver), so a node slower than its camera skips
frames instead of falling behind; decodes, rectifies and maps it exactly as `neoslam run` maps a recorded frame
(the same `StereoFrontEnd` and `NeoSLAM.step`), then publishes (neoslam.live.outputs). With `live.detect_ahead`
(off by default) the network detects objects in the next pair, in a thread of its own, while the current pair is
placed, tracked and mapped: the next pair is taken when that thread is free, so a pair waits for no queue. Given the
same frames it gives the same trajectory, byte for byte, as the offline run. NeoSLAM.step is not changed for it: the
node is a client of the pipeline, as the offline run is.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from neoslam.config import CameraConfig, NeoSLAMConfig
from neoslam.datasets.bag_messages import MessageError, grey_image
from neoslam.errors import ConfigError
from neoslam.live.camera import LiveCamera, live_camera
from neoslam.live.conversions import NS_PER_S, stamp_seconds
from neoslam.live.messages import CompressedImage
from neoslam.live.outputs import Outputs
from neoslam.live.receiver import Counters, Receiver, StereoMessages
from neoslam.live.reporting import LiveStatus, missing_images
from neoslam.live.transport import Ros2Domain
from neoslam.navigation.session import GoalGuidance
from neoslam.perception.detection import ObjectDetector
from neoslam.perception.detector import make_detector
from neoslam.perception.frontend import DetectedPair, StereoFrontEnd, StereoMotion, StereoPair
from neoslam.perception.odometry import StereoOdometry
from neoslam.perception.stereo import ObjectTriangulator
from neoslam.pipeline import NeoSLAM, RunResult, StepObserver
from neoslam.types import Frame, MapState

__all__ = ["LiveNode", "LiveRun", "LiveSource"]

POLL_S = 0.05  # the loop looks at the stop event at least this often while no pair comes
ACK_WAIT_S = 0.2  # at the end, how long reliable readers get to acknowledge the final path and map
ODOMETRY_POLL_S = 0.002
WARM_UP_FRAME = -1  # the frame index of the detector's warm-up image (no frame of a session has it)


@dataclass
class LiveRun:
    """What a live session did: NeoSLAM's result over the frames it processed and how the node kept up."""

    result: RunResult
    counters: Counters
    stamps_ns: list[int]  # header stamp of each processed frame
    latencies_s: np.ndarray  # per processed frame: the pair complete at the receiver -> its pose published
    wall_s: float
    cpu_s: float  # process CPU time (all threads) over the session
    perception: dict[str, float]  # the front end's stage times
    skipped: dict[str, int]  # pairs taken but not mapped, by reason
    stopped_by: str  # signal, frames, idle
    camera: CameraConfig | None


@dataclass(frozen=True)
class LiveSource:
    """The live session as the run's metrics name a dataset: a name, its frames, no ground truth."""

    name: str
    frames: int
    ground_truth: None = None

    def __len__(self) -> int:
        return self.frames


class _TopicMotion:
    """The front end's motion source when an odometry topic gives the motion: the node sets each frame's pose."""

    def __init__(self) -> None:
        self.next_pose = np.eye(4)

    def pose(self, frame_index: int, left: np.ndarray, right: np.ndarray, boxes: np.ndarray) -> np.ndarray:
        return self.next_pose


@dataclass
class _Map:
    """What was last published: the keyframes and closures the map had and when, the closures and relocalisation
    told as events, and whether the map changed since."""

    keyframes: int = -1
    closures: int = 0
    published_s: float = -np.inf
    closure_events: int = 0
    relocalised: bool = False
    pending: bool = False


@dataclass(frozen=True)
class _Detected:
    """A pair as received and its left image's detections."""

    pair: StereoMessages
    objects: DetectedPair


@dataclass(frozen=True)
class _Ahead:
    """A pair whose detection runs in the detection thread."""

    pair: StereoMessages
    running: Future[DetectedPair]

    def detected(self) -> _Detected:
        """Waits for the detection (a network's inference: well under the second a stop may take)."""
        return _Detected(self.pair, self.running.result())


@dataclass
class _Track:
    """The processed frames' stamps and odometry poses (for the path) and the step times (for the result)."""

    stamps_ns: list[int] = field(default_factory=list)
    odometry: list[np.ndarray] = field(default_factory=list)
    step_s: list[float] = field(default_factory=list)
    latencies_s: list[float] = field(default_factory=list)


class LiveNode:
    """NeoSLAM on a live stereo camera over ROS 2: `run(stop)` until `stop` is set (or a frame or idle limit)."""

    def __init__(
        self,
        config: NeoSLAMConfig,
        domain_id: int,
        stored: MapState | None = None,
        session_name: str = "live",
        on_step: StepObserver | None = None,
        warn: Callable[[str], None] = print,
        inform: Callable[[str], None] | None = None,
        on_finish: Callable[[], None] | None = None,
        guidance: GoalGuidance | None = None,
    ) -> None:
        """`on_step(slam, frame, pose)` after each frame (a map file's commits, a viewer); `on_finish()` first thing
        once the session is over (the map's last commit: a stop signal leaves little time); `warn` and `inform`
        print a line (a problem; the first frame mapped). `guidance`: guide to its goal, publishing the route and
        each frame's guidance."""
        if config.perception.detector.source == "file":
            raise ConfigError("the live node detects objects itself: perception.detector.source 'file' is for "
                              "recorded sequences; choose yolox or yolo11")  # fmt: skip
        self.config = config
        self.live = config.live
        self.domain_id = domain_id
        self.stored = stored
        self.session_name = session_name
        self.on_step = on_step
        self.warn = warn
        self.inform = inform
        self.on_finish = on_finish
        self.guidance = guidance
        self._route_shown: Any = None
        self.detector: ObjectDetector = make_detector(config.perception.detector)  # loads the network now
        self._camera: LiveCamera | None = None
        self._front_end: StereoFrontEnd | None = None
        self._first_odometry: np.ndarray | None = None
        self._skipped = {"no_camera_info": 0, "bad_message": 0, "no_odometry": 0}
        self._warned: set[str] = set()

    def run(self, stop: threading.Event, max_frames: int | None = None, idle_exit_s: float | None = None) -> LiveRun:
        """Map until `stop` is set, `max_frames` frames are mapped, or no pair came for `idle_exit_s` after one
        did; then publish the final path and map and return the session."""
        slam = NeoSLAM(self.config, self.stored, self.session_name)  # built before subscribing: it takes a moment
        domain = Ros2Domain(self.domain_id)
        receiver = None
        try:
            outputs = Outputs(domain, self.live, guided=self.guidance is not None)
            domain.start_discovery()
            receiver = Receiver(domain, self.live)
            receiver.start()
            if self.inform is not None:
                topics = ", ".join(receiver.topics.values())
                self.inform(f"listening on ROS domain {self.domain_id} for {topics}")
            return self._loop(stop, slam, receiver, outputs, domain, max_frames, idle_exit_s)
        finally:
            if receiver is not None:
                receiver.stop()
            domain.close()

    def _loop(
        self,
        stop: threading.Event,
        slam: NeoSLAM,
        receiver: Receiver,
        outputs: Outputs,
        domain: Ros2Domain,
        max_frames: int | None,
        idle_exit_s: float | None,
    ) -> LiveRun:
        track, shown = _Track(), _Map()
        status = LiveStatus(self.live, receiver, slam, track.latencies_s, self._skipped)
        started, cpu_started = time.monotonic(), time.process_time()
        last_pair: float | None = None
        stopped_by = "signal"
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="neoslam-detection") as detection:
            ahead: _Ahead | None = None  # the pair whose objects the detection thread is finding
            while not stop.is_set():
                # The newest pair is taken only once the detection thread is free, so it starts at once.
                detected = ahead.detected() if ahead is not None else None
                pair = receiver.mailbox.take(0.0 if detected is not None else POLL_S)
                now = time.monotonic()
                ahead = None if pair is None else self._detect(pair, receiver, detection)
                if pair is not None:
                    last_pair = now
                if ahead is not None and not self.live.detect_ahead:  # one pair at a time
                    detected, ahead = ahead.detected(), None
                if detected is not None:
                    self._map_pair(detected, receiver, slam, outputs, track, shown)
                elif pair is None:
                    self._report_waiting(now - started, receiver, domain)
                    if idle_exit_s is not None and last_pair is not None and now - last_pair > idle_exit_s:
                        stopped_by = "idle"
                        break
                status.publish_when_due(outputs, now, track.stamps_ns[-1] if track.stamps_ns else 0)
                if max_frames is not None and len(track.stamps_ns) >= max_frames:
                    stopped_by = "frames"
                    break
        result = slam.result(np.asarray(track.step_s))
        if self.on_finish is not None:
            self.on_finish()
        stamp = track.stamps_ns[-1] if track.stamps_ns else 0
        outputs.map(result.estimate.poses, track.stamps_ns, result.objects, stamp)
        status.publish(outputs, stamp, final=True)
        outputs.wait_for_readers(ACK_WAIT_S)
        perception = self._front_end.times.summary() if self._front_end is not None else {}
        return LiveRun(
            result=result,
            counters=receiver.counters,
            stamps_ns=track.stamps_ns,
            latencies_s=np.asarray(track.latencies_s),
            wall_s=time.monotonic() - started,
            cpu_s=time.process_time() - cpu_started,
            perception=perception,
            skipped=dict(self._skipped),
            stopped_by=stopped_by,
            camera=self._camera.camera if self._camera is not None else None,
        )

    def _detect(self, pair: StereoMessages, receiver: Receiver, detection: ThreadPoolExecutor) -> _Ahead | None:
        """The pair decoded and rectified, its detection started in the detection thread; None (counted) when it
        cannot be mapped (no calibration yet, a bad message)."""
        if self._camera is None and not self._calibrate(pair, receiver):
            return None
        assert self._camera is not None and self._front_end is not None
        try:
            left, right = self._camera.grey_pair(pair.left, pair.right)
        except MessageError as error:
            self._skip("bad_message", f"a stereo pair at {stamp_seconds(pair.stamp_ns):.3f} s is skipped: {error}")
            return None
        stereo = StereoPair(0, stamp_seconds(pair.stamp_ns), left, right)  # its index is given when it is mapped
        return _Ahead(pair, detection.submit(self._front_end.detected, stereo))

    def _map_pair(
        self, detected: _Detected, receiver: Receiver, slam: NeoSLAM, outputs: Outputs, track: _Track, shown: _Map
    ) -> None:
        """One detected pair placed, tracked and through NeoSLAM, its pose published, the map too if it changed."""
        pair = detected.pair
        assert self._front_end is not None
        if not self._move(pair, receiver, track):
            return
        index = len(track.stamps_ns)
        objects = DetectedPair(replace(detected.objects.pair, index=index), detected.objects.detections)
        frame = self._front_end.moved(self._front_end.triangulated(objects))
        start = time.perf_counter()
        pose = slam.step(frame)
        track.step_s.append(time.perf_counter() - start)
        outputs.pose(frame, pose, pair.stamp_ns)
        track.latencies_s.append(time.monotonic() - pair.received_s)
        track.stamps_ns.append(pair.stamp_ns)
        track.odometry.append(frame.odometry_pose)
        if self.guidance is not None:  # before the other observers: a view shows the frame's guidance
            self._guide(slam, frame, pose, outputs, pair.stamp_ns)
        if self.on_step is not None:
            self.on_step(slam, frame, pose)
        if index == 0 and self.inform is not None:
            self.inform(self._first_frame_line(pair.stamp_ns))
        self._publish_events(slam, outputs, shown, pair.stamp_ns)
        self._publish_map(slam, outputs, track, shown, pair.stamp_ns)

    def _calibrate(self, pair: StereoMessages, receiver: Receiver) -> bool:
        """The stereo calibration from the two CameraInfo messages (once), and the front end for it."""
        infos = receiver.camera_infos()
        if infos is None:
            self._skipped["no_camera_info"] += 1
            return False
        try:
            size = _image_size(pair.left, receiver.image_types["left"])
            types = (receiver.image_types["left"], receiver.image_types["right"])
            self._camera = live_camera(self.live, *infos, types, size)
        except MessageError as error:
            self._skip("bad_message", f"the CameraInfo on {receiver.topics['left_info']} and "
                       f"{receiver.topics['right_info']} cannot be used: {error}")  # fmt: skip
            return False
        camera, perception = self._camera.camera, self.config.perception
        motion = (
            _TopicMotion() if self.live.odometry_topic else StereoMotion(StereoOdometry(camera, perception.odometry))
        )
        triangulator = ObjectTriangulator(camera, perception.stereo)
        self._front_end = StereoFrontEnd(triangulator, self.detector, motion, self.config.motion_limits)
        # The network's first inference at an image size is several times slower than the next: pay it now, on a
        # blank image, rather than on a frame (the detector holds no state between frames).
        self.detector.detect(WARM_UP_FRAME, np.zeros((camera.height, camera.width), dtype=np.uint8))
        return True

    def _move(self, pair: StereoMessages, receiver: Receiver, track: _Track) -> bool:
        """Prepare the motion source for this pair: after a gap the stereo odometry tracks afresh; with an odometry
        topic, the pose at the pair's stamp (False, counted, when the topic has none)."""
        assert self._front_end is not None
        motion = self._front_end.motion
        gap_ns = pair.stamp_ns - track.stamps_ns[-1] if track.stamps_ns else 0
        if isinstance(motion, StereoMotion):
            if gap_ns > self.live.resume_gap_s * NS_PER_S:
                motion.odometry.lose_track()
            return True
        pose = self._odometry_pose(pair.stamp_ns, receiver)
        if pose is None:
            self._skip("no_odometry", f"no odometry on {self.live.odometry_topic} within "
                       f"{self.live.odometry_tolerance_s:g} s of the pair at {stamp_seconds(pair.stamp_ns):.3f} s; "
                       "such pairs are skipped (live.odometry_tolerance_s)")  # fmt: skip
            return False
        if self._first_odometry is None:
            self._first_odometry = np.linalg.inv(pose)  # the session starts at the identity, as a pose file does
        assert isinstance(motion, _TopicMotion)
        motion.next_pose = self._first_odometry @ pose
        return True

    def _odometry_pose(self, stamp: int, receiver: Receiver) -> np.ndarray | None:
        """The odometry at `stamp`, waiting up to live.odometry_wait_s for a message after it."""
        deadline = time.monotonic() + self.live.odometry_wait_s
        while (receiver.odometry.newest_stamp() or -1) < stamp and time.monotonic() < deadline:
            time.sleep(ODOMETRY_POLL_S)
        return receiver.odometry.pose_at(stamp, round(self.live.odometry_tolerance_s * NS_PER_S))

    def _guide(self, slam: NeoSLAM, frame: Frame, pose: np.ndarray, outputs: Outputs, stamp: int) -> None:
        """The frame's guidance published, and the route whenever it is a new one."""
        assert self.guidance is not None
        self.guidance(slam, frame, pose)
        assert self.guidance.latest is not None
        outputs.guidance(self.guidance.latest.row(), stamp)
        route = self.guidance.route
        if route is not None and route is not self._route_shown:
            self._route_shown = route
            outputs.route(route.poses, stamp)

    def _first_frame_line(self, stamp: int) -> str:
        assert self._camera is not None
        camera = self._camera.camera
        raw = self._camera.rectifier is not None and not self._camera.rectifier.identity
        images = "raw images rectified from their CameraInfo" if raw else "rectified images"
        motion = f"odometry from {self.live.odometry_topic}" if self.live.odometry_topic else "stereo odometry"
        size = f"{camera.width}x{camera.height}"
        return f"mapping: first stereo pair at {stamp_seconds(stamp):.3f} s, {size} {images}, {motion}"

    def _skip(self, reason: str, line: str) -> None:
        self._skipped[reason] += 1
        if reason not in self._warned:
            self._warned.add(reason)
            self.warn(line)

    def _report_waiting(self, waited_s: float, receiver: Receiver, domain: Ros2Domain) -> None:
        """One line when no stereo pair has been mapped `no_images_warning_s` after the start."""
        if self._front_end is not None or "waiting" in self._warned or waited_s < self.live.no_images_warning_s:
            return
        self._warned.add("waiting")
        self.warn(missing_images(waited_s, receiver, domain, self.domain_id))

    def _publish_events(self, slam: NeoSLAM, outputs: Outputs, shown: _Map, stamp: int) -> None:
        for closure in slam.loop_closures[shown.closure_events :]:
            outputs.loop_closure(closure, stamp)
        shown.closure_events = len(slam.loop_closures)
        frame = slam.session.relocalised_frame
        if frame is not None and not shown.relocalised:
            shown.relocalised = True
            stored = [c.match_keyframe for c in slam.loop_closures if c.match_keyframe < slam.keyframes.first_id]
            outputs.relocalised(frame, stored[0] if stored else None, stamp)

    def _publish_map(self, slam: NeoSLAM, outputs: Outputs, track: _Track, shown: _Map, stamp: int) -> None:
        """The path and objects when the map changed (a keyframe or a closure), at most every path_period_s."""
        keyframes, closures = len(slam.keyframes.frames), len(slam.loop_closures)
        if (keyframes, closures) != (shown.keyframes, shown.closures):
            shown.pending = True
            shown.keyframes, shown.closures = keyframes, closures
        now = time.monotonic()
        if not shown.pending or now - shown.published_s < self.live.path_period_s:
            return
        stamps = np.asarray(track.stamps_ns, dtype=np.int64)
        trajectory = slam.experience_map.trajectory(stamps / NS_PER_S, np.asarray(track.odometry))
        objects = slam.object_map.objects(slam.experience_map.graph.poses)
        outputs.map(trajectory.poses, track.stamps_ns, objects, stamp)
        shown.published_s, shown.pending = now, False


def _image_size(message: Any, message_type: type) -> tuple[int, int]:
    """(width, height) of an image message (a compressed one is decoded for it)."""
    if message_type is CompressedImage:
        image = grey_image(message, "sensor_msgs/msg/CompressedImage")
        return image.shape[1], image.shape[0]
    return int(message.width), int(message.height)
