"""The sweep spec: a YAML file naming the drives, noise and detection profiles, seeds and config overrides to run.

```yaml
name: kitti-sim                 # a sweep folder holds one named sweep
sources:                        # what each cell drives (paths relative to this file)
  - kitti: ["00", "05"]         # KITTI ground truth: DATA_ROOT/kitti/poses/NN.txt (NEOSLAM_DATA)
  - route: block                # a built-in route
    frames: 300                 # optional: only the first poses (any simulated source)
  - trajectory: my_drive.txt    # a TUM or KITTI pose file (format: auto, times: optional times.txt)
  - dataset: ../kitti_mini      # a dataset run as it is: a simulated dataset folder, a KITTI root, a ROS bag
    sequence: "06"
noise: [vo, heavy]              # odometry noise profiles (simulated sources)
detectors: [real]               # detection profiles (simulated sources)
seeds: [1, 2, 3]                # simulation seeds (simulated sources)
overrides:                      # named config overrides, each a partial NeoSLAM config
  pose_graph: {}
  relaxation: {experience_map: {backend: relaxation}}
config: base.yaml               # optional: a config file under every override
keep_results: false             # keep each cell's results folder (trajectories, map, plots)
columns: [source, noise]        # the summary's groups (default: the axes that vary)
metrics: [ate_rmse_m.corrected, loops.recall]   # the summary's metrics (default: ATE and loop figures)
```

The cells are the grid sources x noise x detectors x seeds x overrides (a dataset source: x overrides only), or,
with `cells:`, a list of picks `{source: NAME, noise: ..., detector: ..., seed: ..., override: ...}` (omitted
axes take the first value of the spec's list). Every mistake is one line naming the spec file and the field.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from neoslam.errors import ConfigError, InputError
from neoslam.text import read_yaml

__all__ = [
    "AXES",
    "DEFAULT_METRICS",
    "KNOWN_METRICS",
    "SourceSpec",
    "CellPick",
    "Spec",
    "SpecError",
    "load_spec",
    "data_root",
]

AXES = ("source", "noise", "detector", "seed", "override")
DEFAULT_METRICS = (
    "ate_rmse_m.odometry",
    "ate_rmse_m.corrected",
    "loops.accepted",
    "loops.false_positive",
    "loops.precision",
    "loops.recall",
)


def _named(prefix: str, *names: str) -> tuple[str, ...]:
    return tuple(f"{prefix}.{name}" for name in names)


_TRAJECTORY = ("ate_rmse_m", "ate_max_m", "rpe_translation_rmse_m", "rpe_rotation_rmse_deg",
               "kitti_translation_percent", "kitti_rotation_deg_per_100m")  # fmt: skip
# The numeric figures of a run's metrics.json that the table holds (`neoslam.commands.run_metrics`; its timing and
# perception figures depend on the machine and go to timing.csv): what `metrics` may name.
KNOWN_METRICS = (
    "frames",
    *_named("ate_rmse_m", "odometry", "corrected"),
    *_named("trajectory.odometry", *_TRAJECTORY),
    *_named("trajectory.corrected", *_TRAJECTORY),
    *_named("loops", "accepted", "true_positive", "false_positive", "revisit_frames", "recalled_frames",
            "precision", "recall", "f1", "recall_at_full_precision", "f1_max"),
    "keyframes",
    *_named("experience_map", "experiences", "links", "links_withdrawn", "closures_rejected_by_grid_cells"),
    "hebbian_bytes",
    "objects",
    "moving_objects",
    "moving_observations",
    *_named("odometry_noise", "heading_rad_per_sqrt_s", "distance_m_per_sqrt_s"),
    *_named("cells", "grid_cells_vs_odometry_rms_m", "grid_cells_vs_odometry_final_m",
            "head_direction_vs_odometry_rms_deg", "ovcn_epochs", "ovcn_loss_first", "ovcn_loss_last",
            "ovcn_held_out_rmse_hz", "ovcn_held_out_max_hz"),
)  # fmt: skip
DATA_ENV = "NEOSLAM_DATA"
DEFAULT_DATA = Path("../shared/data")


class SpecError(ConfigError):
    """A mistake in a sweep spec: one line naming the spec file and the field."""

    def __init__(self, origin: str, field: str, problem: str) -> None:
        self.origin, self.field, self.problem = origin, field, problem
        super().__init__(f"{origin}: {field}: {problem}" if field else f"{origin}: {problem}")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _sequence_name(value: Any) -> Any:
    """YAML reads `kitti: 05` as the number 5: give it back its two digits."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return f"{value:02d}"
    if isinstance(value, list):
        return [_sequence_name(v) for v in value]
    return value


class SourceSpec(_Strict):
    """One entry of `sources`: exactly one of kitti, trajectory, route or dataset, and what applies to it."""

    kitti: str | list[str] | None = Field(None, description="KITTI sequence(s): DATA_ROOT/kitti/poses/NN.txt")
    trajectory: Path | None = Field(None, description="a TUM or KITTI pose file to simulate along")
    route: str | list[str] | None = Field(None, description="built-in route(s): town, block")
    dataset: Path | None = Field(None, description="a dataset run as it is (simulated folder, KITTI root, ROS bag)")
    name: str | None = Field(None, description="the source's name in the table (default: sequence, stem, route)")
    format: Literal["auto", "kitti", "tum"] = Field("auto", description="format of `trajectory`")
    times: Path | None = Field(None, description="KITTI times.txt for `trajectory`")
    frames: int | None = Field(None, gt=1, description="simulate only the first this many poses")
    sequence: str | None = Field(None, description="KITTI sequence of a `dataset` that is a KITTI root")
    detections: Path | None = Field(None, description="detections file (JSON lines) for a `dataset`")
    odometry: Path | None = Field(None, description="odometry poses for a `dataset`")

    @field_validator("kitti", "sequence", mode="before")
    @classmethod
    def _two_digits(cls, value: Any) -> Any:
        return _sequence_name(value)

    @model_validator(mode="after")
    def _one_kind(self) -> SourceSpec:
        kinds = [k for k in ("kitti", "trajectory", "route", "dataset") if getattr(self, k) is not None]
        if len(kinds) != 1:
            raise ValueError("give exactly one of kitti, trajectory, route or dataset")
        kind = kinds[0]
        for key in ("kitti", "route"):
            value = getattr(self, key)
            if isinstance(value, list) and (not value or len(set(value)) != len(value)):
                raise ValueError(f"{key}: needs at least one name, each once")
            if isinstance(value, list) and len(value) > 1 and self.name is not None:
                raise ValueError(f"name: applies to one {key} source, not a list")
        rules = {
            "format": ("trajectory",),
            "times": ("trajectory",),
            "frames": ("kitti", "trajectory", "route"),
            "sequence": ("dataset",),
            "detections": ("dataset",),
            "odometry": ("dataset",),
        }
        for field, kinds_allowed in rules.items():
            if field in self.model_fields_set and kind not in kinds_allowed:
                raise ValueError(f"{field}: applies to {' or '.join(kinds_allowed)} sources, not to {kind}")
        return self

    @property
    def kind(self) -> str:
        return next(k for k in ("kitti", "trajectory", "route", "dataset") if getattr(self, k) is not None)


class CellPick(_Strict):
    """One cell of a `cells:` list; omitted axes take the first value of the spec's list."""

    source: str
    noise: str | None = None
    detector: str | None = None
    seed: int | None = None
    override: str | None = None

    @field_validator("source", mode="before")
    @classmethod
    def _two_digits(cls, value: Any) -> Any:
        return _sequence_name(value)


class Spec(_Strict):
    """A sweep: see the module's docstring for the YAML form."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9._-]+$")
    sources: list[SourceSpec] = Field(min_length=1)
    noise: list[str] = Field(["vo"], min_length=1)
    detectors: list[str] = Field(["real"], min_length=1)
    seeds: list[int] = Field([1], min_length=1)
    overrides: dict[str, dict[str, Any]] = Field({"default": {}}, min_length=1)
    cells: list[CellPick] | None = Field(None, min_length=1, description="a list of cells instead of the grid")
    config: Path | None = Field(None, description="a NeoSLAM config file under every override")
    data_root: Path | None = Field(None, description="where kitti/poses lives (default: $NEOSLAM_DATA)")
    keep_results: bool = False
    columns: list[str] | None = Field(None, description="the summary's groups; default: the axes that vary")
    metrics: list[str] = Field(list(DEFAULT_METRICS), min_length=1, description="the summary's metrics")
    base_dir: Path = Field(Path("."), exclude=True, description="where relative paths start (the spec's folder)")
    origin: str = Field("sweep spec", exclude=True, description="what error messages name (the spec file)")

    @field_validator("noise", "detectors", "seeds")
    @classmethod
    def _distinct(cls, values: list) -> list:
        seen = set()
        for value in values:
            if value in seen:
                raise ValueError(f"each value once ({value!r} is given twice)")
            seen.add(value)
        return values

    @field_validator("overrides", mode="before")
    @classmethod
    def _none_is_empty(cls, value: Any) -> Any:
        if isinstance(value, dict):
            return {k: ({} if v is None else v) for k, v in value.items()}
        return value

    @field_validator("columns")
    @classmethod
    def _axes(cls, columns: list[str] | None) -> list[str] | None:
        for column in columns or ():
            if column not in AXES:
                raise ValueError(f"{column!r} is not an axis; choose from {', '.join(AXES)}")
        return columns

    def path(self, value: Path) -> Path:
        """A path of the spec, relative to the spec's folder."""
        return value if value.is_absolute() else self.base_dir / value

    def resolved_data_root(self) -> Path:
        return data_root(self.path(self.data_root) if self.data_root is not None else None)

    def error(self, field: str, problem: str) -> SpecError:
        return SpecError(self.origin, field, problem)


def data_root(given: Path | None = None) -> Path:
    """The shared data folder: given, else $NEOSLAM_DATA, else ../shared/data from the working folder."""
    if given is not None:
        return given
    return Path(os.environ.get(DATA_ENV, DEFAULT_DATA))


def _where(location: tuple[Any, ...]) -> str:
    text = ""
    for part in location:
        if isinstance(part, int):
            text += f"[{part}]"
        elif not str(part).startswith(("function-", "model-")):  # pydantic's validator names, not fields
            text += f".{part}" if text else str(part)
    return text


def parse_spec(values: Any, origin: str = "sweep spec", base_dir: Path = Path(".")) -> Spec:
    """A spec from its YAML mapping; one line naming the origin and the field if it is wrong."""
    if not isinstance(values, dict):
        raise SpecError(origin, "", "a sweep spec must be a mapping (name, sources, noise, ...)")
    try:
        return Spec.model_validate({**values, "base_dir": base_dir, "origin": origin})
    except ValidationError as error:
        first = error.errors()[0]
        message = first["msg"].removeprefix("Value error, ")
        if first["type"] == "extra_forbidden":
            message = "unknown field"
        raise SpecError(origin, _where(first["loc"]), message) from None


def load_spec(path: Path) -> Spec:
    """Read and check a spec file (the per-cell checks, files and configs, come with `expand`)."""
    if not path.exists():
        raise SpecError(str(path), "", "spec file not found")
    if path.is_dir():
        raise SpecError(str(path), "", "is a folder, not a spec file")
    if not path.is_file():  # a pipe would wait for a writer that may never come
        raise SpecError(str(path), "", "not a regular file (a pipe or a device?); give a spec file")
    try:
        values = read_yaml(path)
    except InputError as error:
        raise SpecError(str(path), f"line {error.line}" if error.line is not None else "", error.problem) from None
    return parse_spec(values, str(path), path.parent)
