"""Odometry links grow uncertain with the time they span as well as the metres: at the odometry noise per root second
the moving-object tracks allow for (stated, raised by their online estimate), whichever term is larger."""

from __future__ import annotations

import numpy as np
import pytest

from neoslam.config import ExperienceMapConfig
from neoslam.mapping.pose_graph import ODOMETRY_YAW_SIGMA_FLOOR_RAD, link_sigmas
from neoslam.types import Link

CONFIG = ExperienceMapConfig()
HEAVY = (0.032, 0.32)  # rad and m per root second: the simulator's `heavy` odometry


def odometry_link(metres: float, seconds: float) -> Link:
    return Link(0, 1, np.eye(4), "odometry", metres, seconds)


def test_a_robot_standing_still_drifts_with_time() -> None:
    still = odometry_link(0.0, 16.0)
    assert link_sigmas(still, CONFIG)[2] == ODOMETRY_YAW_SIGMA_FLOOR_RAD  # by distance alone: rigid
    sigmas = link_sigmas(still, CONFIG, HEAVY)
    assert sigmas[2] == pytest.approx(HEAVY[0] * 4.0) and sigmas[3:] == pytest.approx([HEAVY[1] * 4.0] * 3)


def test_the_larger_of_the_distance_and_the_time_terms_holds() -> None:
    fast = odometry_link(100.0, 1.0)  # 100 m in a second: the distance term is larger
    assert link_sigmas(fast, CONFIG, HEAVY) == pytest.approx(link_sigmas(fast, CONFIG))
    slow = odometry_link(1.0, 100.0)
    assert link_sigmas(slow, CONFIG, HEAVY)[2] == pytest.approx(HEAVY[0] * 10.0)


def test_loop_links_keep_their_own_sigmas() -> None:
    loop = Link(0, 1, np.eye(4), "loop", 0.0)
    assert link_sigmas(loop, CONFIG, HEAVY) == pytest.approx(link_sigmas(loop, CONFIG))


@pytest.mark.slow
def test_a_drive_with_heavy_odometry_weighs_its_links_by_the_estimated_noise(tmp_path) -> None:
    """The block route with the simulator's `heavy` odometry, the config stating `vo`'s noise: the pose graph takes
    the noise the tracks estimate, and its odometry links span the drive's time."""
    from neoslam.config import NeoSLAMConfig
    from neoslam.config.profiles import simulation_config
    from neoslam.datasets.simulated import read_dataset, write_dataset
    from neoslam.pipeline import NeoSLAM
    from neoslam.sim.simulator import simulate_route

    config = simulation_config(NeoSLAMConfig(experience_map={"odometry_weights": "estimated"}), "heavy", 3, "real")
    write_dataset(tmp_path / "data", simulate_route("block", config.simulator))
    frames = list(read_dataset(tmp_path / "data").frames())
    slam = NeoSLAM(config)
    for frame in frames:
        slam.step(frame)
    noise = slam.experience_map.backend.odometry_noise
    assert noise == slam.moving_objects.odometry_noise()
    assert noise[0] > 3 * config.moving_objects.odometry_heading_noise  # drawn: ten times the stated
    graph = slam.experience_map.graph
    spanned = sum(link.duration_s for link in graph.links if link.kind == "odometry")
    assert 0 < spanned <= frames[-1].timestamp - frames[0].timestamp + 1e-9

    by_distance = config.experience_map.model_copy(update={"odometry_weights": "distance"})
    unweighted = NeoSLAM(config.model_copy(update={"experience_map": by_distance}))
    for frame in frames[:50]:
        unweighted.step(frame)
    assert unweighted.experience_map.backend.odometry_noise is None
