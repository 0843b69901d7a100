"""Object-vector cells network (OVCN, paper 3.4): a feed-forward regression network learns the firing field of an
object-vector cell (eq. 7-10) from the vectors to the objects of keyframes (eq. 11-13), and gives the keyframe
template activity O^k that the Hebbian memory ties to the grid and head-direction cells (paper 3.5).

Each object activates one object-vector cell (the paper's simplification), so one network models the field.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
from numpy.typing import ArrayLike
from pydantic import ValidationError
from torch import nn

from neoslam.config import CameraConfig, ObjectVectorConfig
from neoslam.errors import InputError

__all__ = [
    "MIN_OBJECT_DISTANCE",
    "MAX_OBJECT_DISTANCE",
    "object_vector_field",
    "synthetic_keyframe_batches",
    "ObjectVectorCells",
]

_CAMERA = CameraConfig()
MIN_OBJECT_DISTANCE = _CAMERA.min_range  # m: nearer objects fill the view and are not reported
MAX_OBJECT_DISTANCE = _CAMERA.max_range  # m: farther objects are not reported
MAX_OBJECTS_PER_KEYFRAME = 3  # synthetic keyframes: the current object and up to two within e_max (paper 3.2)
_DTYPE = torch.float32
_LINEAR_INIT_SLOPE = math.sqrt(5)  # the `a` of nn.Linear's default kaiming_uniform_ initialisation
_CHECKPOINT_KIND = "neoslam.object_vector_cells"
_CHECKPOINT_VERSION = 1


def object_vector_field(distance: ArrayLike, direction: ArrayLike, config: ObjectVectorConfig) -> np.ndarray:
    """Ground-truth firing rate of eq. 7, Hz, of an object at `distance` (m) and allocentric `direction` (rad).

    d of eq. 7 is the robot's vector to the object minus the cell's preferred vector, both in the world plane.
    """
    distance = np.asarray(distance, dtype=float)
    direction = np.asarray(direction, dtype=float)
    preferred = config.preferred_direction
    offset_x = distance * np.cos(direction) - config.preferred_distance * np.cos(preferred)
    offset_y = distance * np.sin(direction) - config.preferred_distance * np.sin(preferred)
    # R of eq. 9 turns the offset into components along and across the preferred direction.
    along = np.cos(preferred) * offset_x + np.sin(preferred) * offset_y
    across = -np.sin(preferred) * offset_x + np.cos(preferred) * offset_y
    sigma_across = config.field_sigma_across or config.field_sigma
    quadratic = along**2 / (2 * config.field_sigma**2) + across**2 / (2 * sigma_across**2)  # dᵀ A d, eq. 8, 10
    return config.peak_rate * np.exp(-quadratic) + config.baseline_rate  # eq. 7


def synthetic_keyframe_batches(
    config: ObjectVectorConfig,
    rng: np.random.Generator,
    *,
    epochs: int | None = None,
    min_distance: float = MIN_OBJECT_DISTANCE,
    max_distance: float = MAX_OBJECT_DISTANCE,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Object vectors (distances, directions) of `keyframes_per_epoch` keyframes per epoch, for tests and benchmarks.

    Objects lie at uniform distances within the camera's range and in every direction around the robot.
    """
    batches = []
    for _ in range(config.epochs if epochs is None else epochs):
        objects = int(rng.integers(1, MAX_OBJECTS_PER_KEYFRAME + 1, size=config.keyframes_per_epoch).sum())
        distances = rng.uniform(min_distance, max_distance, size=objects)
        directions = rng.uniform(-math.pi, math.pi, size=objects)
        batches.append((distances, directions))
    return batches


class _Network(nn.Module):
    """Eq. 12 with N hidden ELU units (one ELU unit cannot fit a bump) and a linear read-out of the firing rate."""

    def __init__(self, inputs: int, hidden_units: int) -> None:
        super().__init__()
        # skip_init: weights are drawn from the cells' own generator, never from torch's global one.
        self.hidden = nn.utils.skip_init(nn.Linear, inputs, hidden_units, dtype=_DTYPE)
        self.output = nn.utils.skip_init(nn.Linear, hidden_units, 1, dtype=_DTYPE)

    def initialise(self, generator: torch.Generator) -> None:
        """torch's default nn.Linear initialisation, drawn from `generator`."""
        for layer in (self.hidden, self.output):
            nn.init.kaiming_uniform_(layer.weight, a=_LINEAR_INIT_SLOPE, generator=generator)
            bound = 1 / math.sqrt(layer.in_features)
            nn.init.uniform_(layer.bias, -bound, bound, generator=generator)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.output(nn.functional.elu(self.hidden(inputs))).squeeze(-1)


def _input_width(config: ObjectVectorConfig) -> int:
    return 3 if config.direction_encoding == "cos_sin" else 2


def _build_optimizer(config: ObjectVectorConfig, network: nn.Module) -> torch.optim.Optimizer:
    if config.optimizer == "adam":
        return torch.optim.Adam(network.parameters(), lr=config.learning_rate)
    return torch.optim.SGD(network.parameters(), lr=config.learning_rate)


def _as_vectors(distances: ArrayLike, directions: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    distances = np.atleast_1d(np.asarray(distances, dtype=float))
    directions = np.atleast_1d(np.asarray(directions, dtype=float))
    if distances.shape != directions.shape or distances.ndim != 1:
        raise ValueError(f"distances {distances.shape} and directions {directions.shape} must be equal 1-D shapes")
    return distances, directions


class ObjectVectorCells:
    """The OVCN: learns the firing field of eq. 7 from object vectors and predicts the cells' firing rates."""

    def __init__(self, config: ObjectVectorConfig | None = None) -> None:
        self.config = config or ObjectVectorConfig()
        self._generator = torch.Generator().manual_seed(self.config.seed)
        self._network = _Network(_input_width(self.config), self.config.hidden_units)
        self._network.initialise(self._generator)
        self._optimizer = _build_optimizer(self.config, self._network)
        self.loss_history: list[float] = []  # mean loss of eq. 13 per epoch (paper Fig. 4a)

    def _encode(self, distances: np.ndarray, directions: np.ndarray) -> torch.Tensor:
        """X of eq. 11, scaled: d / distance_scale and φ as (cos, sin) or as raw radians / π in [-1, 1)."""
        scaled = distances / self.config.distance_scale
        if self.config.direction_encoding == "cos_sin":
            columns = [scaled, np.cos(directions), np.sin(directions)]
        else:
            wrapped = np.mod(directions + math.pi, 2 * math.pi) - math.pi
            columns = [scaled, wrapped / math.pi]
        return torch.from_numpy(np.stack(columns, axis=1)).to(_DTYPE)

    def train_epoch(self, distances: ArrayLike, directions: ArrayLike) -> float:
        """One pass over the object vectors in shuffled mini-batches; returns the epoch's mean loss of eq. 13."""
        distances, directions = _as_vectors(distances, directions)
        if not len(distances):
            raise ValueError("an epoch needs at least one object vector")
        inputs = self._encode(distances, directions)
        targets = torch.from_numpy(object_vector_field(distances, directions, self.config)).to(_DTYPE)  # y_t
        order = torch.randperm(len(inputs), generator=self._generator)
        self._network.train()
        total = 0.0
        for batch in torch.split(order, self.config.batch_size):
            loss = 0.5 * (targets[batch] - self._network(inputs[batch])).square().mean()  # eq. 13
            self._optimizer.zero_grad()
            loss.backward()
            self._optimizer.step()
            total += loss.item() * len(batch)
        self.loss_history.append(total / len(inputs))
        return self.loss_history[-1]

    def train(self, keyframe_batches: Iterable[tuple[ArrayLike, ArrayLike]]) -> list[float]:
        """One epoch per (distances, directions) batch of keyframe objects; returns the loss of each epoch."""
        return [self.train_epoch(distances, directions) for distances, directions in keyframe_batches]

    def respond(self, distances: ArrayLike, directions: ArrayLike) -> np.ndarray:
        """Predicted firing rates O_t (eq. 12), Hz, of the cells activated by objects at these vectors."""
        distances, directions = _as_vectors(distances, directions)
        self._network.eval()
        with torch.no_grad():
            return self._network(self._encode(distances, directions)).double().numpy()

    def template_activity(self, distances: ArrayLike, directions: ArrayLike) -> float:
        """O^k = (1/N) Σ O_i^k over the N objects of a keyframe (paper 3.5), Hz."""
        rates = self.respond(distances, directions)
        if not len(rates):
            raise ValueError("a keyframe template needs at least one object")
        return float(rates.mean())

    def held_out_error(
        self,
        grid_size: int = 64,
        min_distance: float = MIN_OBJECT_DISTANCE,
        max_distance: float = MAX_OBJECT_DISTANCE,
    ) -> dict[str, float]:
        """RMSE and max abs error, Hz, against eq. 7 on a regular grid_size² (distance, direction) grid."""
        distance, direction = np.meshgrid(
            np.linspace(min_distance, max_distance, grid_size),
            np.linspace(-math.pi, math.pi, grid_size, endpoint=False),
        )
        error = (
            self.respond(distance.ravel(), direction.ravel())
            - object_vector_field(distance, direction, self.config).ravel()
        )
        return {"rmse_hz": float(np.sqrt(np.mean(error**2))), "max_abs_hz": float(np.abs(error).max())}

    def state_dict(self) -> dict[str, torch.Tensor]:
        """The network's weights and biases (W and b of eq. 12), as copies."""
        return {name: tensor.detach().clone() for name, tensor in self._network.state_dict().items()}

    def weights(self) -> dict[str, np.ndarray]:
        """The network's parameters as arrays, by name (a map file stores them)."""
        return {name: tensor.detach().numpy().copy() for name, tensor in self._network.state_dict().items()}

    def restore(self, weights: dict[str, np.ndarray], loss_history: list[float]) -> None:
        """Take the parameters and the epochs learnt of a stored map: its epochs count towards `epochs`."""
        self._network.load_state_dict({name: torch.from_numpy(np.array(value)) for name, value in weights.items()})
        self.loss_history = [float(loss) for loss in loss_history]

    def save(self, path: str | Path) -> None:
        """Weights, optimiser and generator state, config and loss history, so training resumes exactly."""
        torch.save(
            {
                "kind": _CHECKPOINT_KIND,
                "version": _CHECKPOINT_VERSION,
                "config": self.config.model_dump(mode="json"),
                "network": self._network.state_dict(),
                "optimizer": self._optimizer.state_dict(),
                "generator": self._generator.get_state(),
                "loss_history": list(self.loss_history),
            },
            path,
        )

    @classmethod
    def load(cls, path: str | Path) -> ObjectVectorCells:
        """A network written by `save`; tensors and plain values only (weights_only)."""
        state = _read_checkpoint(Path(path))
        try:
            cells = cls(ObjectVectorConfig.model_validate(state["config"]))
        except ValidationError as error:
            raise InputError(path, f"invalid object-vector config ({error.error_count()} errors)") from None
        cells._network.load_state_dict(state["network"])
        cells._optimizer.load_state_dict(state["optimizer"])
        cells._generator.set_state(state["generator"])
        cells.loss_history = [float(loss) for loss in state["loss_history"]]
        return cells


def _read_checkpoint(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, "object-vector cells file not found")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # torch raises pickle, runtime and zip errors alike for a foreign file
        raise InputError(path, f"not an object-vector cells file ({error.__class__.__name__})") from None
    if not isinstance(state, dict) or state.get("kind") != _CHECKPOINT_KIND:
        raise InputError(path, "not an object-vector cells file")
    if state.get("version") != _CHECKPOINT_VERSION:
        raise InputError(path, f"unsupported object-vector cells file version {state.get('version')}")
    return state
