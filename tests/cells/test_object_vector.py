"""Object-vector cells network: the field of eq. 7-10 by hand, learning it (eq. 11-13), determinism, persistence."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from neoslam.cells.object_vector import ObjectVectorCells, object_vector_field, synthetic_keyframe_batches
from neoslam.config import ObjectVectorConfig
from neoslam.errors import InputError

PEAK_HZ = 1.2  # a of eq. 7
ONE_SIGMA = math.exp(-0.5)  # exp(-dᵀAd) one σ from the preferred vector
# Enough object vectors to learn the field (160k, about 1 s); the paper's 10 x 20 keyframes only learn its floor.
FIT_CONFIG = ObjectVectorConfig(epochs=400, keyframes_per_epoch=200, learning_rate=0.01, batch_size=32)
FIT_RMSE_HZ = 0.04  # measured 0.031 Hz, against the 1.2 Hz peak
FIT_MAX_ABS_HZ = 0.2  # measured 0.11 Hz, at the top of the bump
SHORT_CONFIG = ObjectVectorConfig(epochs=3, keyframes_per_epoch=20)


def trained(config: ObjectVectorConfig, data_seed: int = 0) -> tuple[ObjectVectorCells, list[float]]:
    cells = ObjectVectorCells(config)
    losses = cells.train(synthetic_keyframe_batches(config, np.random.default_rng(data_seed)))
    return cells, losses


@pytest.fixture(scope="module")
def fitted() -> tuple[ObjectVectorCells, list[float]]:
    return trained(FIT_CONFIG)


def test_field_peaks_at_the_preferred_vector():
    config = ObjectVectorConfig(preferred_distance=12.0, preferred_direction=2.0, baseline_rate=0.1)
    rate = object_vector_field(12.0, 2.0, config)
    assert rate == pytest.approx(PEAK_HZ + 0.1)  # a + b


def test_field_one_sigma_along_and_across_the_preferred_direction():
    config = ObjectVectorConfig(preferred_distance=10.0, preferred_direction=0.5, field_sigma=4.0)
    along = object_vector_field(14.0, 0.5, config)
    across = object_vector_field(math.hypot(10.0, 4.0), 0.5 + math.atan2(4.0, 10.0), config)
    np.testing.assert_allclose([along, across], PEAK_HZ * ONE_SIGMA)


def test_elliptical_field_uses_the_across_sigma_sideways():
    config = ObjectVectorConfig(preferred_distance=10.0, field_sigma=4.0, field_sigma_across=2.0)
    sideways = object_vector_field(math.hypot(10.0, 2.0), math.atan2(2.0, 10.0), config)
    assert sideways == pytest.approx(PEAK_HZ * ONE_SIGMA)


def test_field_matches_the_matrix_form_of_eq_7_to_10():
    config = ObjectVectorConfig(preferred_distance=8.0, preferred_direction=-1.1, field_sigma=3.0)
    distance, direction = 11.0, -0.7
    d = distance * np.array([math.cos(direction), math.sin(direction)]) - 8.0 * np.array(
        [math.cos(-1.1), math.sin(-1.1)]
    )
    rotation = np.array([[math.cos(-1.1), math.sin(-1.1)], [-math.sin(-1.1), math.cos(-1.1)]])  # eq. 9
    a_matrix = rotation.T @ np.diag([1 / (2 * 3.0**2)] * 2) @ rotation  # eq. 8, 10
    expected = PEAK_HZ * math.exp(-d @ a_matrix @ d)  # eq. 7, b = 0
    assert object_vector_field(distance, direction, config) == pytest.approx(expected)


def test_field_is_continuous_across_plus_minus_pi():
    config = ObjectVectorConfig(preferred_direction=math.pi)
    assert object_vector_field(10.0, math.pi, config) == pytest.approx(object_vector_field(10.0, -math.pi, config))


@pytest.mark.slow
def test_training_loss_falls_and_the_field_is_learnt(fitted):
    cells, losses = fitted
    assert len(losses) == FIT_CONFIG.epochs and cells.loss_history == losses
    assert losses[-1] < 0.05 * losses[0]
    error = cells.held_out_error(grid_size=64)
    assert error["rmse_hz"] < FIT_RMSE_HZ
    assert error["max_abs_hz"] < FIT_MAX_ABS_HZ
    assert cells.respond([10.0], [0.0])[0] == pytest.approx(PEAK_HZ, abs=FIT_MAX_ABS_HZ)


def test_paper_budget_loss_falls():
    cells, losses = trained(ObjectVectorConfig())  # lr 0.001, 10 epochs of 20 keyframes, Adam, one object per step
    assert len(losses) == 10
    assert np.mean(losses[-3:]) < 0.5 * losses[0]


def test_same_seed_gives_identical_weights_and_losses():
    first, first_losses = trained(SHORT_CONFIG)
    second, second_losses = trained(SHORT_CONFIG)
    assert first_losses == second_losses
    for name, tensor in first.state_dict().items():
        assert torch.equal(tensor, second.state_dict()[name]), name
    other = ObjectVectorCells(SHORT_CONFIG.model_copy(update={"seed": 1}))
    assert not torch.equal(other.state_dict()["hidden.weight"], first.state_dict()["hidden.weight"])


def test_training_leaves_torch_global_random_state_alone():
    before = torch.random.get_rng_state()
    trained(SHORT_CONFIG)
    assert torch.equal(torch.random.get_rng_state(), before)


def test_save_and_load_round_trip_gives_identical_responses_and_resumes_exactly(tmp_path):
    cells, _ = trained(SHORT_CONFIG)
    path = tmp_path / "ovcn.pt"
    cells.save(path)
    loaded = ObjectVectorCells.load(path)
    distances, directions = np.linspace(1, 40, 50), np.linspace(-math.pi, math.pi, 50)
    np.testing.assert_array_equal(loaded.respond(distances, directions), cells.respond(distances, directions))
    assert loaded.config == cells.config and loaded.loss_history == cells.loss_history
    more = synthetic_keyframe_batches(SHORT_CONFIG, np.random.default_rng(7), epochs=2)
    assert loaded.train(more) == cells.train(more)


def test_load_refuses_missing_and_foreign_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        ObjectVectorCells.load(tmp_path / "absent.pt")
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(InputError, match="not an object-vector cells file"):
        ObjectVectorCells.load(foreign)
    text = tmp_path / "text.pt"
    text.write_text("hello")
    with pytest.raises(InputError, match="not an object-vector cells file"):
        ObjectVectorCells.load(text)


def test_template_activity_is_the_mean_of_the_object_responses(fitted):
    cells, _ = fitted
    distances, directions = np.array([9.0, 12.0, 30.0]), np.array([0.1, -0.2, 2.5])
    assert cells.template_activity(distances, directions) == pytest.approx(cells.respond(distances, directions).mean())
    with pytest.raises(ValueError, match="at least one object"):
        cells.template_activity([], [])


def test_mismatched_inputs_are_refused():
    cells = ObjectVectorCells(SHORT_CONFIG)
    with pytest.raises(ValueError, match="equal 1-D shapes"):
        cells.respond([1.0, 2.0], [0.0])
    with pytest.raises(ValueError, match="at least one object vector"):
        cells.train_epoch([], [])
