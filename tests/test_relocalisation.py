"""Two sessions in one simulated world (NeoSLAM with a stored map, in memory; the map file is tests/store and
tests/test_cli_map.py): the second starts elsewhere, in its own frame, with its own noise, relocalises in the first
one's map and ends in its frame; a session whose world the map never saw never joins it; a session driving a mapped
street the other way joins the map once and keeps its heading."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.simulated import write_dataset
from neoslam.geometry import invert_pose, yaw_of
from neoslam.sim.routes import ROUTES, Route, drive_route
from neoslam.sim.session_drives import session_recordings
from neoslam.types import Trajectory

TRUE_PLACE_M = 5.0  # a closure is true when its two frames are this close in the ground truth
SAME_PLACE_M = 2.0  # a frame of B drives A's street when it passes this close to a frame of A (ground truth)
CONFIG = NeoSLAMConfig()  # the config town_session_a was driven with


@pytest.mark.slow
def test_a_later_session_relocalises_in_the_stored_map_and_ends_in_its_frame(
    town_sessions, town_session_a, session_driver
):
    (a, b), (_, folder_b) = town_sessions.sessions, town_sessions.folders
    stored, result_a = town_session_a  # A driven alone with the default config
    state, result = session_driver(folder_b, CONFIG, stored, b.recording.name)
    relocalised = result.session.relocalised_frame
    assert result.session.id == 2 and relocalised is not None and relocalised < 400
    # B's trajectory is in A's frame: where B drives A's streets, B's estimate lies where A's estimate has the same
    # place (A's map is itself off the ground truth by its drift, which B inherits).
    truth_in_a = invert_pose(a.start_pose) @ b.to_world(b.recording.truth.poses)
    truth_a = a.recording.truth.poses
    gaps = np.linalg.norm(truth_in_a[relocalised:, None, :2, 3] - truth_a[None, :, :2, 3], axis=2)
    on_street = gaps.min(axis=1) < SAME_PLACE_M
    same_place = gaps.argmin(axis=1)[on_street]
    estimate_b = result.estimate.positions[relocalised:][on_street]
    disagreement = np.linalg.norm(estimate_b - result_a.estimate.positions[same_place], axis=1)
    assert on_street.sum() > 100 and np.median(disagreement) < 2.0, (on_street.sum(), np.median(disagreement))
    # Every closure with the stored map joins true places.
    map_closures = [c for c in result.loop_closures if c.match_keyframe < result.first_keyframe]
    assert map_closures
    for closure in map_closures:
        gap = truth_in_a[closure.query_frame, :2, 3] - truth_a[closure.match_frame, :2, 3]
        assert np.linalg.norm(gap) < TRUE_PLACE_M
    # The session's keyframes and experiences joined the map with ids after the stored ones.
    assert [s.id for s in state.sessions] == [1, 2] and state.sessions[1].relocalised_frame == relocalised
    assert min(k.id for k in result.keyframes) == stored.next_keyframe
    assert {e.session for e in state.experiences[len(stored.experiences) :]} == {2}
    assert any(c.session == 2 and c.match_session == 1 for c in state.closures)


@pytest.mark.slow
def test_a_session_in_a_world_the_map_never_saw_never_joins_it(town_session_a, session_driver, tmp_path):
    stored, _ = town_session_a  # town session A driven alone with the default config
    poses = stored.experience_poses.copy()
    other = simulation_config(CONFIG, "vo", 9).simulator  # another seed: another world of objects
    truth = drive_route(ROUTES["block"], other.frame_period, other.camera.height_above_ground)
    elsewhere = session_recordings(truth, [(0, len(truth))], other, [9], "block")[0]
    write_dataset(tmp_path / "b", elsewhere.recording)
    state, result = session_driver(tmp_path / "b", CONFIG, stored, elsewhere.recording.name)
    assert result.session.relocalised_frame is None
    assert result.loop_closures == result.session_closures()
    assert np.array_equal(state.experience_poses[: len(poses)], poses), "the stored part moved"


def _there_and_back(route: Route, frame_period: float, camera_height: float) -> Trajectory:
    """A flat route driven to its end, then back along itself facing the other way (the turn itself left out: the
    two passes are two sessions)."""
    out = drive_route(route, frame_period, camera_height)
    turned = np.diag([-1.0, -1.0, 1.0, 1.0])  # half a turn about the robot's vertical
    back = out.poses[::-1] @ turned
    stamps = np.concatenate([out.timestamps, out.timestamps[-1] + frame_period + out.timestamps])
    return Trajectory(stamps, np.concatenate([out.poses, back]))


@pytest.mark.slow
def test_a_session_driving_a_mapped_street_the_other_way_joins_the_map_once_and_keeps_its_heading(
    session_driver, tmp_path
):
    # Session B starts where A's drive ended and drives A's L-shaped street back to its start: every place it
    # recognises, it sees from the other side. Relocalising joins it to A's map for good: its later closures link
    # into the map as loop closures (they used to join it again each time, moving the whole session by that one
    # fit, and the rounding error of those joins doubled each time until the poses blew up).
    config = simulation_config(CONFIG, "vo", 3)
    street = Route("street", "an L-shaped street", ((0.0, 0.0), (200.0, 0.0), (200.0, 100.0)))
    sim = config.simulator
    truth = _there_and_back(street, sim.frame_period, sim.camera.height_above_ground)
    half = len(truth) // 2
    a, b = session_recordings(truth, [(0, half), (half, len(truth))], sim, [3, 4], "street")
    for session, name in ((a, "a"), (b, "b")):
        write_dataset(tmp_path / name, session.recording)
    stored, result_a = session_driver(tmp_path / "a", config, None, a.recording.name)
    _, result = session_driver(tmp_path / "b", config, stored, b.recording.name)
    relocalised = result.session.relocalised_frame
    assert relocalised is not None and relocalised < half // 2
    assert len(result.experience_map.parts.roots()) == 1, "the session stayed a part of the map of its own"
    into_map = [c for c in result.loop_closures if c.match_keyframe < result.first_keyframe]
    assert len(into_map) > 1, "no closures with the map after the join"
    # From relocalising on, B's estimate lies where A's has the same place (A's map is off the truth by its own
    # drift, which B inherits), turned half a turn from A's heading there.
    truth_in_a = (invert_pose(a.start_pose) @ b.to_world(b.recording.truth.poses))[relocalised:]
    same_place = np.linalg.norm(truth_in_a[:, None, :2, 3] - a.recording.truth.poses[None, :, :2, 3], axis=2)
    estimate, estimate_a = result.estimate.poses[relocalised:], result_a.estimate.poses[same_place.argmin(axis=1)]
    disagreement = np.linalg.norm(estimate[:, :2, 3] - estimate_a[:, :2, 3], axis=1)
    turn = np.angle(np.exp(1j * (yaw_of(estimate) - yaw_of(estimate_a) - np.pi)))
    assert disagreement.max() < 5.0, disagreement.max()
    assert np.degrees(np.abs(turn)).max() < 5.0, np.degrees(np.abs(turn)).max()
