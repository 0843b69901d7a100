"""experience_map.g2o read back with GTSAM's own g2o reader: one vertex per experience at its corrected pose, one
edge per link with the link's measured relative pose and, as noise, the sigmas the pose-graph back end gives it."""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np
import pytest

from neoslam.commands.run import with_backend
from neoslam.config import NeoSLAMConfig
from neoslam.config.profiles import simulation_config
from neoslam.datasets.simulated import read_dataset, write_dataset
from neoslam.io.g2o import link_information, write_g2o
from neoslam.mapping.experience_map import ExperienceMap
from neoslam.mapping.pose_graph import link_sigmas
from neoslam.pipeline import run
from neoslam.sim.routes import ROUTES, drive_route
from neoslam.sim.simulator import simulate

BLOCK_FRAMES = 600  # the block route up to its first revisit of the start: a few loop closures


@pytest.fixture(scope="module")
def experience_map(tmp_path_factory: pytest.TempPathFactory) -> ExperienceMap:
    """The map of the simulated block route (vo noise, the rich `ideal` street, pose-graph back end)."""
    config = with_backend(simulation_config(NeoSLAMConfig(), "vo", 2, "ideal"), "pose-graph")
    sim = config.simulator
    truth = drive_route(ROUTES["block"], sim.frame_period, sim.camera.height_above_ground)
    folder = tmp_path_factory.mktemp("g2o") / "block"
    write_dataset(folder, simulate(truth.subset(np.arange(BLOCK_FRAMES)), sim, name="block", source="test"))
    dataset = read_dataset(folder)
    return run(dataset.frames(), config, total=len(dataset), progress=False).experience_map


@pytest.fixture(scope="module")
def read_back(experience_map: ExperienceMap, tmp_path_factory: pytest.TempPathFactory):
    path = tmp_path_factory.mktemp("g2o_file") / "experience_map.g2o"
    write_g2o(path, experience_map)
    graph, initial = gtsam.readG2o(str(path), True)
    return path, graph, initial


@pytest.mark.slow
def test_vertices_are_the_corrected_experience_poses(experience_map: ExperienceMap, read_back) -> None:
    _, _, initial = read_back
    poses = experience_map.graph.poses
    assert initial.size() == len(experience_map.experiences) == len(poses) > 1
    for index, pose in enumerate(poses):
        np.testing.assert_allclose(initial.atPose3(index).matrix(), pose, rtol=0, atol=1e-12)


def test_edges_are_the_links_with_their_sigmas(experience_map: ExperienceMap, read_back) -> None:
    _, graph, _ = read_back
    links = experience_map.graph.links
    assert graph.size() == len(links)
    assert {link.kind for link in links} == {"odometry", "loop"}  # the run closed loops: both kinds are checked
    for index, link in enumerate(links):
        factor = graph.at(index)
        assert list(factor.keys()) == [link.source, link.target]
        np.testing.assert_allclose(factor.measured().matrix(), link.relative, rtol=0, atol=1e-12)
        sigmas = factor.noiseModel().sigmas()  # GTSAM's order: rotation, then translation
        np.testing.assert_allclose(sigmas, link_sigmas(link, experience_map.config), rtol=1e-9)


def test_the_file_format(experience_map: ExperienceMap, read_back) -> None:
    path, _, _ = read_back
    lines = path.read_text().splitlines()
    vertices = [line for line in lines if line.startswith("VERTEX_SE3:QUAT ")]
    edges = [line.split() for line in lines if line.startswith("EDGE_SE3:QUAT ")]
    assert len(vertices) == len(experience_map.experiences) and lines[-1] == "FIX 0"
    assert {len(line.split()) for line in vertices} == {9} and {len(edge) for edge in edges} == {3 + 7 + 21}
    # g2o orders the information translation first: the first diagonal entry is 1 / sigma_x^2
    link = experience_map.graph.links[0]
    assert float(edges[0][10]) == pytest.approx(1.0 / link_sigmas(link, experience_map.config)[3] ** 2)
    assert np.allclose(np.diag(link_information(link, experience_map.config))[:3], float(edges[0][10]))


def test_an_empty_map_is_an_empty_file(tmp_path: Path) -> None:
    config = NeoSLAMConfig()
    empty = ExperienceMap(config.experience_map, tuple(config.grid_cells.dims), config.head_direction.cells)
    write_g2o(tmp_path / "empty.g2o", empty)
    assert (tmp_path / "empty.g2o").read_text() == ""
