"""Moving objects (beyond the paper): a car driving past or a person walking is no landmark. Each observation is
followed over a few frames in the odometry frame, which is accurate over a short stretch; an object whose position
drifts across its observations beyond what their stereo noise allows is moving, and its observations join no
keyframe and no map object.

- An observation's centre (moved from the visible surface to the object's middle with the class footprints, as
  keyframes do) goes to the odometry frame with the frame's odometry pose. Its uncertainty is the object map's
  depth std along the viewing ray (stereo error grows with depth squared, or the front end's own when larger, never
  below `position_sigma_floor`) and the floor across it.
- Observations join tracks of their label, one each, nearest first, inside a gate around the track's prediction:
  `gate_radius` across the viewing ray, `gate_sigmas` depth stds along it (at least the radius). A track predicts
  with its fitted velocity shrunk by its significance (1 - (k/m)^2, m its Mahalanobis norm, k
  `prediction_sigmas`): a static object's noisy velocity counts for nothing (else a far track wanders off and
  takes other objects' views), a fast car's for almost all of it, so a car doing 1 m a frame stays on its track;
  a track not yet judged (below `judge_after` views) predicts with none.
- Per track, the last `track_length` observations are fitted with a constant velocity by weighted least squares
  in the ground plane (each observation weighted by its inverse covariance, long along its ray, grown by the
  odometry's error since it was made: `odometry_heading_noise` turns it about the robot by its range times the
  heading error, `odometry_distance_noise` shifts it; both random walks, so the older a view, the less it weighs
  and the less a velocity it fixes; else heavy odometry noise makes parked cars 30 m off seem to move). With
  `odometry_noise: estimated` those two are floors, raised by the estimate of mapping/odometry_noise.py from how
  slow tracks' views drift. From `judge_after` observations on, a track moves when its velocity is
  `significance_sigmas` stds from zero and at least `min_speed` (`label_min_speed` for walkers); once moving it
  stays so (a car waiting at a light is still traffic). The velocity's
  covariance grows by the fit's reduced chi-square where the views scatter beyond their noise, and a view that
  falls in two tracks' gates restarts its track's fit (far views of objects in a row can swap tracks, which then
  seem to move).
- A track not judged moving whose velocity is `hold_sigmas` stds from zero and fast enough is undecided: its
  views are held out too (a far oncoming car needs a second of views to be judged at 30 m).
- The views a track let through before it was found moving (or held) are taken back out of the keyframe window
  (`LocalObjectWindow.retract`), with those of the track it broke off from: three early views of a car make a
  window object that would otherwise stay in keyframes for the window's length. The object map keeps them.
- With `unjudged: wait`, the views a track let through are settled in the keyframe window once the track is known
  to be static (`_proven_static`: judged, and its speed plus `static_sigmas` stds below `min_speed`); a window
  object with no settled view is provisional in keyframes (no contradiction to a match when missing). A track
  known to be static is no predecessor of a new one (its views are not taken back with a car's).
- With `window_scatter` set (off by default), a keyframe-window object none of whose views is settled is moving
  too when its views came within `window_span` seconds and scatter about their best common point beyond
  `window_scatter` (reduced chi-square, each view's stereo noise grown by the odometry's error since, as above): it
  joins no keyframe (`window_views_move`, which the keyframe builder asks). A car detected only now and then
  breaks its track every few frames, each piece's first views pass before it can be judged, and the window fuses
  them into an object of their own.
- Tracks end when unseen for `max_unseen` seconds; at most `max_tracks` are kept. Moving tracks are kept as a small
  record (label, last view, frame) to be reported in the corrected map. Deterministic: no randomness, ties broken
  by track and observation order.
"""

from __future__ import annotations

import numpy as np

from neoslam.config import MovingObjectsConfig, ObjectMapConfig
from neoslam.geometry import camera_points_to_robot, transform_points
from neoslam.loop.keyframes import LocalObjectWindow, WindowViews, object_centres
from neoslam.mapping.object_map import MapObject, depth_sigmas
from neoslam.mapping.odometry_noise import OdometryNoiseEstimate
from neoslam.types import Frame, ObjectObservation

__all__ = ["MovingObjectDetector"]


def _stereo_covariance(rays: np.ndarray, along: np.ndarray, across: float) -> np.ndarray:
    """(n, 2, 2) covariances of ground-plane positions: `along` std on the unit ray, `across` off it."""
    outer = rays[:, :, None] * rays[:, None, :]
    return outer * along[:, None, None] ** 2 + (np.eye(2) - outer) * across**2


class MovingObjectDetector:
    """Short tracks of the observations in the odometry frame; `static(frame)` is what keyframes and the map see."""

    def __init__(
        self,
        config: MovingObjectsConfig,
        object_map: ObjectMapConfig,
        footprints: dict[str, tuple[float, float]] | None = None,
    ) -> None:
        self.config = config
        self.object_map = object_map
        self.footprints = footprints
        slots, length = config.max_tracks, config.track_length
        self._labels: list[str | None] = [None] * slots
        self._live = np.zeros(slots, dtype=bool)
        self._moving = np.zeros(slots, dtype=bool)
        self._min_speed = np.full(slots, config.min_speed)  # the track's label's
        self._seen = np.zeros(slots, dtype=int)  # observations ever joined
        self._fitted = np.zeros(slots, dtype=int)  # observations in the fit (since the last ambiguous one)
        self._last_time = np.zeros(slots)
        self._times = np.zeros((slots, length))
        self._points = np.zeros((slots, length, 2))
        self._covariance = np.zeros((slots, length, 2, 2))  # stereo only, odometry's added at the fit
        self._rays = np.zeros((slots, length, 2))  # unit, from the robot
        self._ranges = np.zeros((slots, length))  # m, from the robot
        self._held = np.zeros((slots, length), dtype=bool)  # False: an empty entry of the ring
        self._rows = np.zeros((slots, length), dtype=int)  # the frame (count of frames given) of each entry
        # The fit, at the time of the track's last observation: position, velocity as predicted with, Mahalanobis
        # norm of the velocity, speed.
        self._position = np.zeros((slots, 2))
        self._velocity = np.zeros((slots, 2))
        self._significance = np.zeros(slots)
        self._speed = np.zeros(slots)
        self._speed_bound = np.full(slots, np.inf)  # speed + static_sigmas stds of the velocity along its worst axis
        self._last_view = np.zeros((slots, 3))  # last observed centre, robot frame
        self._last_row = np.zeros(slots, dtype=int)  # the frame (count of frames given) it was seen in
        self._moving_id = np.full(slots, -1)  # numbered in the order the tracks were found moving
        self._next_moving_id = 0
        self._reported: list[tuple[int, str, np.ndarray, int, int]] = []  # ended moving tracks
        self._passed: list[list[ObjectObservation]] = [[] for _ in range(slots)]  # views let through, latest
        self._unsettled: list[list[ObjectObservation]] = [[] for _ in range(slots)]  # let through, not settled
        self._frames = 0
        self.flagged = 0  # observations kept out as moving (or held while undecided)
        self.retracted = 0  # views let through earlier, taken back out of the keyframe window
        self.noise_estimate = OdometryNoiseEstimate(config.noise_window, config.noise_min_views, config.noise_bins)

    def static(self, frame: Frame, window: LocalObjectWindow | None = None) -> tuple[ObjectObservation, ...]:
        """The frame's observations of objects not judged moving (all of them when disabled). The views of a track
        let through before it was found moving are taken back out of the keyframe `window`: three early views
        of a car make a window object that would stay in keyframes for the window's length. The views a track let
        through are settled in the window once it is known to be static (`unjudged: wait`)."""
        if not self.config.enabled:
            return frame.observations
        kept_out, tracks = self._kept_out(frame)
        self.flagged += int(kept_out.sum())
        for slot in np.unique(tracks[kept_out]):
            if self._passed[slot] and window is not None:
                self.retracted += window.retract(tuple(self._passed[slot]))
            self._passed[slot], self._unsettled[slot] = [], []
        length = self.config.track_length
        proven = self._proven_static(tracks)
        for observation, slot, out, static in zip(frame.observations, tracks, kept_out, proven, strict=True):
            if out:
                continue
            self._passed[slot] = [*self._passed[slot][1 - length :], observation]
            if static and window is not None:  # the views before this frame's: this one joins the window next
                window.settle(tuple(self._unsettled[slot]))
                self._unsettled[slot] = []
            self._unsettled[slot] = [*self._unsettled[slot][1 - length :], observation]
        return tuple(o for o, out in zip(frame.observations, kept_out, strict=True) if not out)

    def update(self, frame: Frame) -> np.ndarray:
        """Track the frame's observations; per observation, True when it is kept out (moving, undecided, or not
        judged yet with `unjudged: out`)."""
        return self._kept_out(frame)[0]

    def _kept_out(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """Per observation, whether it is kept out, and its track."""
        row, self._frames = self._frames, self._frames + 1
        self._end_unseen(frame.timestamp)
        observations = frame.observations
        if not observations:
            return np.zeros(0, dtype=bool), np.zeros(0, dtype=int)
        centres = np.array([o.center_camera for o in observations], dtype=float)
        if self.footprints is not None:
            centres = object_centres(observations, self.footprints)
        in_robot = camera_points_to_robot(centres)
        points = transform_points(frame.odometry_pose, in_robot)[:, :2]
        rays = points - frame.odometry_pose[:2, 3]
        ranges = np.linalg.norm(rays, axis=1)
        rays /= np.maximum(ranges, 1e-9)[:, None]
        sigmas = depth_sigmas(observations, self.object_map)  # as the object map weighs them
        labels = [o.label for o in observations]
        tracks, ambiguous = self._assign(labels, points, rays, sigmas, frame.timestamp)
        covariance = _stereo_covariance(rays, sigmas, self.object_map.position_sigma_floor)
        if self.config.odometry_noise == "estimated":
            self._observe_odometry_error(tracks, ambiguous, points, rays, ranges, row, frame.timestamp)
        for j, track in enumerate(tracks):
            if track < 0:
                predecessor = self._predecessor(labels[j], points[j], frame.timestamp, tracks)
                tracks[j] = self._start(labels[j])
                self._passed[tracks[j]] = list(self._passed[predecessor]) if predecessor >= 0 else []
            if ambiguous[j]:
                self._restart_fit(tracks[j])
            self._append(tracks[j], frame.timestamp, points[j], covariance[j], rays[j], ranges[j], in_robot[j], row)
        self._fit(tracks)
        self._judge(tracks)
        unjudged_out = (self._seen[tracks] < self.config.judge_after) & (self.config.unjudged == "out")
        return self._moving[tracks] | self._suspect(tracks) | unjudged_out, tracks

    def _proven_static(self, slots: np.ndarray) -> np.ndarray:
        """Tracks judged whose speed, `static_sigmas` stds of their velocity added, is below min_speed: a car far
        ahead coming on moves its few views mostly along the viewing ray, where stereo depth is least sure, so three
        views of it are not moving enough to be judged so, yet not enough to know it parked either."""
        judged = self._seen[slots] >= self.config.judge_after
        return judged & ~self._moving[slots] & (self._speed_bound[slots] < self._min_speed[slots])

    def _suspect(self, slots: np.ndarray) -> np.ndarray:
        """Tracks not (yet) judged moving whose velocity is `hold_sigmas` stds from zero and fast enough: a car
        still far and noisy; its views are held out until the evidence is in (a view let into a keyframe stays
        in its window for window_length metres)."""
        config = self.config
        fast = self._speed[slots] >= self._min_speed[slots]
        return ~self._moving[slots] & fast & (self._significance[slots] >= config.hold_sigmas)

    def _assign(
        self, labels: list[str], points: np.ndarray, rays: np.ndarray, sigmas: np.ndarray, time: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Per observation, the live track it joins (-1: none): pairs of one label inside the gate, nearest (in
        distance scaled by the gate) first, a track and an observation in one pair at most; and whether that was
        ambiguous (the observation in the gate of another track too, or the track's gate holding another
        observation: far, noisy views of objects in a row can swap tracks, which then seem to move)."""
        live = np.flatnonzero(self._live)
        assigned = np.full(len(points), -1)
        if len(live) == 0:
            return assigned, np.zeros(len(points), dtype=bool)
        predicted = self._position[live] + self._velocity[live] * (time - self._last_time[live])[:, None]
        offsets = predicted[:, None, :] - points[None, :, :]  # (tracks, observations, 2)
        along = np.einsum("toi,oi->to", offsets, rays)
        across_squared = np.maximum(np.einsum("toi,toi->to", offsets, offsets) - along**2, 0.0)
        radius = self.config.gate_radius
        along_gate = np.maximum(radius, self.config.gate_sigmas * sigmas)
        score = (along / along_gate) ** 2 + across_squared / radius**2
        same_label = np.array([[self._labels[t] == label for label in labels] for t in live])
        inside = same_label & (score <= 1.0)
        track_rows, observation_rows = np.nonzero(inside)
        order = np.lexsort((observation_rows, track_rows, score[track_rows, observation_rows]))
        taken = np.zeros(len(live), dtype=bool)
        for t, o in zip(track_rows[order], observation_rows[order], strict=True):
            if not taken[t] and assigned[o] < 0:
                taken[t], assigned[o] = True, live[t]
        crowded = (inside.sum(axis=0) > 1) | (inside.sum(axis=1) > 1)[np.searchsorted(live, np.maximum(assigned, 0))]
        return assigned, (assigned >= 0) & crowded

    def _predecessor(self, label: str, point: np.ndarray, time: float, taken: np.ndarray) -> int:
        """The live track of the label, not seen this frame, that could have reached `point` at `max_speed`
        (nearest first; -1: none): a car's track may break while its velocity is still unsure, and the views it
        let through must be taken back with the new track's when that one is found moving."""
        candidates = np.flatnonzero(self._live & ~self._proven_static(np.arange(len(self._live))))
        candidates = [s for s in candidates if self._labels[s] == label and s not in taken]
        if not candidates:
            return -1
        slots = np.asarray(candidates)
        distance = np.linalg.norm(self._position[slots] - point, axis=1)
        reach = self.config.gate_radius + self.config.max_speed * (time - self._last_time[slots])
        inside = distance <= reach
        return int(slots[inside][np.argmin(distance[inside])]) if inside.any() else -1

    def _start(self, label: str) -> int:
        """A new track in a free slot, or in the one unseen the longest when all are taken."""
        free = np.flatnonzero(~self._live)
        slot = int(free[0]) if len(free) else int(np.argmin(self._last_time))
        if self._live[slot]:
            self._end(np.array([slot]))
        self._labels[slot] = label
        self._min_speed[slot] = self.config.label_min_speed.get(label, self.config.min_speed)
        self._live[slot], self._moving[slot], self._seen[slot] = True, False, 0
        self._restart_fit(slot)
        self._velocity[slot], self._significance[slot], self._speed[slot] = 0.0, 0.0, 0.0
        self._speed_bound[slot] = np.inf
        self._moving_id[slot] = -1
        self._passed[slot], self._unsettled[slot] = [], []
        return slot

    def _restart_fit(self, slot: int) -> None:
        """Forget the track's observations in the fit (not its velocity, which it goes on predicting with)."""
        self._held[slot] = False
        self._fitted[slot] = 0

    def _append(
        self,
        slot: int,
        time: float,
        point: np.ndarray,
        covariance: np.ndarray,
        ray: np.ndarray,
        distance: float,
        view: np.ndarray,
        row: int,
    ) -> None:
        entry = self._seen[slot] % self.config.track_length  # a ring: the oldest observation leaves
        self._times[slot, entry], self._points[slot, entry] = time, point
        self._covariance[slot, entry], self._rays[slot, entry], self._ranges[slot, entry] = covariance, ray, distance
        self._held[slot, entry] = True
        self._seen[slot] += 1
        self._fitted[slot] = min(self._fitted[slot] + 1, self.config.track_length)
        self._last_time[slot], self._last_view[slot], self._last_row[slot] = time, view, row
        self._rows[slot, entry] = row

    def _observe_odometry_error(
        self, tracks: np.ndarray, ambiguous: np.ndarray, points: np.ndarray, rays: np.ndarray, ranges: np.ndarray,
        row: int, time: float,
    ) -> None:  # fmt: skip
        """For the noise estimate, the displacements across the line from the robot of this frame's views of tracks
        slower than `noise_max_speed`: over a long interval, from the track's latest view at least `noise_lag`
        frames old, and over the intervals at its ends, to the view after that one and from the track's last view.
        Not only tracks not found moving: under heavy odometry noise those are the near ones, and the far parked
        cars the heading error moves most would be left out."""
        usable = np.flatnonzero((tracks >= 0) & ~ambiguous)
        usable = usable[self._speed[tracks[usable]] < self.config.noise_max_speed]
        slots = tracks[usable]
        rows = np.where(self._held[slots], self._rows[slots], -1)
        old = np.where(rows <= row - self.config.noise_lag, rows, -1)
        first = old.argmax(axis=1)  # the latest view old enough
        later = np.where(rows > old.max(axis=1, keepdims=True), rows, np.iinfo(int).max)
        after, last = later.argmin(axis=1), rows.argmax(axis=1)  # the view after that one, and the latest
        # a view old enough, and two more after it (else the two short intervals would be one)
        keep = (old.max(axis=1) >= 0) & (later.min(axis=1) < rows.max(axis=1))
        if not keep.any():
            return
        slots, views, entries = slots[keep], usable[keep], [first[keep], after[keep], last[keep]]
        at = [self._points[slots, e] for e in entries] + [points[views]]
        robot_then = at[0] - self._rays[slots, entries[0]] * self._ranges[slots, entries[0], None]
        arms = at[3] - (robot_then + points[views] - rays[views] * ranges[views, None]) / 2.0
        lengths = np.linalg.norm(arms, axis=1)
        across = np.stack([-arms[:, 1], arms[:, 0]], axis=1) / np.maximum(lengths, 1e-9)[:, None]
        times = [self._times[slots, e] for e in entries] + [np.full(len(slots), time)]
        longer = (times[3] - times[0]) - ((times[1] - times[0]) + (times[3] - times[2])) / 2.0

        def displacement(start: int, end: int) -> np.ndarray:
            return np.einsum("ni,ni->n", at[end] - at[start], across)

        self.noise_estimate.add(lengths, displacement(0, 3), displacement(0, 1), displacement(2, 3), longer)

    def window_views_move(self, views: WindowViews) -> bool:
        """Whether a keyframe-window object's views show it moving: seen within `window_span` seconds and
        scattered about their best common point beyond `window_scatter` (reduced chi-square), each view's stereo
        covariance grown by the odometry's error since it was made (heading error turning it about the robot by
        its range, distance error shifting it), as a track's views are."""
        config = self.config
        n = len(views.times)
        if config.window_scatter <= 0 or n < 2 or np.ptp(views.times) >= config.window_span:
            return False
        arms = views.points - views.robots
        ranges = np.linalg.norm(arms, axis=1)
        rays = arms / np.maximum(ranges, 1e-9)[:, None]
        age = views.times.max() - views.times
        information = np.linalg.inv(self._with_odometry_error(views.covariances, rays, ranges, age))
        total = information.sum(axis=0)
        weighted = np.einsum("nij,nj->ni", information, views.points)
        best = np.linalg.solve(total, weighted.sum(axis=0))  # the point the views agree on best
        offsets = views.points - best
        chi_square = float(np.einsum("ni,nij,nj->", offsets, information, offsets))
        return chi_square > config.window_scatter * 2 * (n - 1)

    def odometry_noise(self) -> tuple[float, float]:
        """The heading (rad) and distance (m) random walks per square root of a second the tracks allow for: as
        stated, or the online estimate where it is larger (`odometry_noise: estimated`)."""
        config = self.config
        stated = config.odometry_heading_noise, config.odometry_distance_noise
        estimate = self.noise_estimate.noise() if config.odometry_noise == "estimated" else None
        if estimate is None:
            return stated
        return max(stated[0], estimate[0]), max(stated[1], estimate[1])

    def _fit(self, slots: np.ndarray) -> None:
        """Constant-velocity weighted least squares of each track's observations, relative to its last one (time
        and place): position now, velocity, its Mahalanobis norm; the velocity predicted with is shrunk by that
        norm and bounded by `max_speed`. Where the observations scatter about the fitted line more than their noise
        allows (a track that took another object's view, or a far view's skewed stereo depth), the velocity's
        covariance grows by the reduced chi-square (the Birge ratio): a jump is no velocity."""
        last = (self._seen - 1) % self.config.track_length
        single = slots[self._fitted[slots] == 1]
        self._position[single] = self._points[single, last[single]]  # a single view: the object is where it was seen
        slots = slots[self._fitted[slots] >= 2]
        if len(slots) == 0:
            return
        tau = self._times[slots] - self._last_time[slots, None]
        origin = self._points[slots, last[slots]]
        points = self._points[slots] - origin[:, None]
        info = self._information(slots, -tau)
        normal = np.zeros((len(slots), 4, 4))
        normal[:, :2, :2] = info.sum(axis=1)
        normal[:, :2, 2:] = np.einsum("sl,slij->sij", tau, info)
        normal[:, 2:, :2] = normal[:, :2, 2:]
        normal[:, 2:, 2:] = np.einsum("sl,slij->sij", tau**2, info)
        weighted = np.einsum("slij,slj->sli", info, points)
        rhs = np.concatenate([weighted.sum(axis=1), np.einsum("sl,sli->si", tau, weighted)], axis=1)
        covariance = np.linalg.inv(normal)
        solution = np.einsum("sij,sj->si", covariance, rhs)
        velocity = solution[:, 2:]
        residuals = points - solution[:, None, :2] - tau[:, :, None] * velocity[:, None, :]
        misfit = np.einsum("sli,slij,slj->s", residuals, info, residuals)
        freedom = 2 * self._fitted[slots] - 4
        scatter = np.maximum(1.0, misfit / np.maximum(freedom, 1))  # beyond the noise: no constant velocity
        inverse = np.linalg.inv(covariance[:, 2:, 2:])
        widest = np.sqrt(np.linalg.eigvalsh(covariance[:, 2:, 2:])[:, -1] * scatter)
        significance = np.sqrt(np.einsum("si,sij,sj->s", velocity, inverse, velocity) / scatter)
        mean = np.linalg.solve(normal[:, :2, :2], rhs[:, :2, None])[:, :, 0]  # constant position: weighted mean
        sure = self.config.prediction_sigmas / np.maximum(significance, 1e-9)
        # Two views fix a velocity with no check of their scatter (a view of the next car makes one): a track
        # predicts with none before it is judged.
        judged = self._fitted[slots] >= self.config.judge_after
        shrink = np.where(judged, np.clip(1.0 - sure**2, 0.0, 1.0), 0.0)[:, None]
        speed = np.linalg.norm(velocity, axis=1)
        bounded = np.minimum(1.0, self.config.max_speed / np.maximum(speed, 1e-9))[:, None]
        self._position[slots] = origin + (1.0 - shrink) * mean + shrink * solution[:, :2]
        self._velocity[slots] = shrink * bounded * velocity
        self._significance[slots], self._speed[slots] = significance, speed
        self._speed_bound[slots] = speed + self.config.static_sigmas * widest

    def _information(self, slots: np.ndarray, age: np.ndarray) -> np.ndarray:
        """(s, l, 2, 2) inverse covariances of the tracks' observations relative to their last one, `age` s before
        it: stereo noise, and the odometry's since (a heading random walk turns a view about the robot, by its range
        times the heading error; the distance error shifts it), taken as independent per observation (the shared
        part of two views' odometry errors is left out). Zero for empty entries of the ring."""
        covariance = self._with_odometry_error(self._covariance[slots], self._rays[slots], self._ranges[slots], age)
        held = self._held[slots]
        covariance[~held] = np.eye(2)  # any invertible matrix: the entry is zeroed below
        return np.linalg.inv(covariance) * held[..., None, None]

    def _with_odometry_error(
        self, covariance: np.ndarray, rays: np.ndarray, ranges: np.ndarray, age: np.ndarray
    ) -> np.ndarray:
        """(..., 2, 2) stereo covariances of views on unit `rays` at `ranges` grown by the odometry's error over
        the `age` s since: a heading random walk turns a view about the robot by its range times the heading error,
        the distance error shifts it."""
        heading_noise, distance_noise = self.odometry_noise()
        across = np.stack([-rays[..., 1], rays[..., 0]], axis=-1)
        turned = (heading_noise * ranges) ** 2 * age
        moved = distance_noise**2 * age
        return (
            covariance
            + turned[..., None, None] * across[..., :, None] * across[..., None, :]
            + moved[..., None, None] * np.eye(2)
        )

    def _judge(self, slots: np.ndarray) -> None:
        """Tracks old enough to judge whose velocity is significant and fast enough move from now on."""
        config = self.config
        judged = self._fitted[slots] >= config.judge_after
        moves = (
            judged
            & (self._significance[slots] >= config.significance_sigmas)
            & (self._speed[slots] >= self._min_speed[slots])
        )
        for slot in slots[moves & ~self._moving[slots]]:
            self._moving[slot], self._moving_id[slot] = True, self._next_moving_id
            self._next_moving_id += 1

    def _end_unseen(self, time: float) -> None:
        self._end(np.flatnonzero(self._live & (time - self._last_time > self.config.max_unseen)))

    def _end(self, slots: np.ndarray) -> None:
        for slot in slots[self._moving[slots]]:
            label = self._labels[slot]
            assert label is not None
            record = (int(self._moving_id[slot]), label, self._last_view[slot].copy(), int(self._last_row[slot]))
            self._reported.append((*record, int(self._seen[slot])))
            self._moving_id[slot] = -1
        self._live[slots] = False
        self._moving[slots] = False
        for slot in slots:
            self._passed[slot], self._unsettled[slot] = [], []

    def objects(self, poses: np.ndarray) -> list[MapObject]:
        """Every moving object, where it was last seen in the map of `poses` (one T_world_robot per frame given,
        in order: the corrected trajectory), ordered by id."""
        live = [
            (int(self._moving_id[s]), self._labels[s], self._last_view[s], int(self._last_row[s]), int(self._seen[s]))
            for s in np.flatnonzero(self._live & self._moving)
        ]
        records = sorted(self._reported + live, key=lambda record: record[0])
        return [
            MapObject(identity, str(label), transform_points(poses[row], view[None])[0], seen)
            for identity, label, view, row, seen in records
        ]
