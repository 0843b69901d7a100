"""Navigation on a running NeoSLAM: a route from where the robot is, guidance frame by frame while the drive goes on
(planning again as it leaves the route), and a later session that has not relocalised yet."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.datasets.simulated import read_dataset
from neoslam.errors import GoalError
from neoslam.navigation import Guide, RoutePlanner, plan_route, pose_in_map
from neoslam.pipeline import NeoSLAM

pytestmark = pytest.mark.slow  # a whole simulated drive


def test_routes_and_guidance_follow_a_running_map(block_seed5):
    config = NeoSLAMConfig()
    slam = NeoSLAM(config)
    frames = list(read_dataset(block_seed5).frames())
    for frame in frames[:400]:
        pose = slam.step(frame)
    planner = RoutePlanner(slam)
    route = planner.plan("start")
    assert route.start == slam.experience_map.current and route.goal.experience == 0
    assert route.length_m > 0
    np.testing.assert_allclose(route.poses, slam.experience_map.graph.poses[route.experiences])
    guide = Guide(route, config.navigation, planner.replan)
    records = [guide.update(pose_in_map(slam, pose))]
    for frame in frames[400:]:
        pose = slam.step(frame)
        records.append(guide.update(pose_in_map(slam, pose)))
    states = {r.state for r in records}
    assert "not_localised" not in states and "unreachable" not in states
    assert records[0].state == "on_route"
    assert "replanned" in states  # the drive goes on round the block, away from the route back to the start
    assert len(slam.experience_map.experiences) > len(planner.graph) - 1  # the planner follows the growing map
    # the map as stored plans the same: a route on a MapState from the robot's experience
    stored = plan_route(slam.map_state(), "start", start=slam.experience_map.current)
    assert stored.experiences.tolist() == plan_route(slam, "start").experiences.tolist()


def test_a_later_session_is_not_localised_until_it_relocalises(block_seed5):
    first = NeoSLAM(NeoSLAMConfig())
    frames = list(read_dataset(block_seed5).frames())
    for frame in frames[:200]:
        first.step(frame)
    later = NeoSLAM(NeoSLAMConfig(), stored=first.map_state())
    pose = later.step(frames[0])
    assert later.session.id == 2 and pose_in_map(later, pose) is None
    with pytest.raises(GoalError, match="not localised in the map yet"):
        plan_route(later, "start")
    assert plan_route(later, "start of session 1", start=0).length_m == 0.0  # a place of the map: fine
