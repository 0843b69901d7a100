"""A spec expanded into cells, each with a stable id: the hash of its inputs' content, its resolved config, the code
version and the measurement. Cells that drive the same simulated dataset share a simulation key.

A grid can hold hundreds of thousands of cells that differ only in their seed: the config of each (noise, detector,
override) is checked once, and a cell keeps its seed and a reference to that shared setting, its config made when
it runs."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import cache
from itertools import product
from pathlib import Path
from typing import Annotated, Any

from pydantic import TypeAdapter, ValidationError

import neoslam
from neoslam.config import MAP_SECTIONS, NeoSLAMConfig, SimulatorConfig, config_values, merge_settings
from neoslam.config.calibration import detection_profile, noise_profile
from neoslam.errors import NeoSLAMError
from neoslam.sweep.spec import AXES, KNOWN_METRICS, Spec, _where

__all__ = ["Source", "Setting", "Cell", "Plan", "expand", "code_version", "content_hash", "DEFAULT_MEASURE"]

DEFAULT_MEASURE = "neoslam.commands.run.run_dataset"

# Config sections that only the run reads: a simulation is shared by cells that differ in these alone.
RUN_ONLY_SECTIONS = frozenset({"perception", *MAP_SECTIONS, "evaluation"})
ID_LENGTH = 16
# Stands for a cell's seed in the canonical JSON of a shared setting; quoted as JSON quotes it.
SEED_MARK = "\x00seed\x00"
_SEED_TOKEN = json.dumps(SEED_MARK)
_SEEDS = TypeAdapter(list[Annotated[int, SimulatorConfig.model_fields["seed"]]])


def _framed(part: Any) -> bytes:
    """A part as `content_hash` hashes it: its length, then its canonical JSON (bytes as they are)."""
    data = part if isinstance(part, bytes) else json.dumps(part, sort_keys=True, default=str).encode()
    return len(data).to_bytes(8, "little") + data


def content_hash(*parts: Any) -> str:
    """sha256 of the canonical JSON of the parts (bytes hashed as they are)."""
    return hashlib.sha256(b"".join(_framed(part) for part in parts)).hexdigest()


class _SeededHash:
    """`content_hash(*head, JSON with the seed, *tail)` for seed after seed: what comes before the seed is hashed once
    per length of the seed's digits, so that a cell costs a few hundred bytes of hashing, not the whole config."""

    def __init__(self, head: tuple[Any, ...], text: str, seeded: bool, tail: tuple[Any, ...]) -> None:
        before, _, after = text.partition(_SEED_TOKEN) if seeded else (text, "", "")
        self.seeded, self.before, self.after = seeded, before.encode(), after.encode()
        self.start = hashlib.sha256(b"".join(_framed(part) for part in head))
        self.tail = b"".join(_framed(part) for part in tail)
        self.states: dict[int, Any] = {}  # the hash after the bytes before the seed, by the data's length

    def __call__(self, seed: int | None) -> str:
        digits = str(seed).encode() if self.seeded else b""
        length = len(self.before) + len(digits) + len(self.after)
        state = self.states.get(length)
        if state is None:
            state = self.states[length] = self.start.copy()
            state.update(length.to_bytes(8, "little") + self.before)
        digest = state.copy()
        digest.update(digits + self.after + self.tail)
        return digest.hexdigest()


@cache
def code_version() -> str:
    """neoslam's version and a hash of its installed source files: a cell whose code changed runs again."""
    package = Path(neoslam.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(package.rglob("*.py")):
        digest.update(str(path.relative_to(package)).encode() + b"\0" + path.read_bytes() + b"\0")
    return f"{neoslam.__version__}+{digest.hexdigest()[:12]}"


@dataclass(frozen=True)
class Source:
    """A resolved entry of `sources`: what a worker needs to make or open its dataset. Pose files travel as bytes
    (a cell may run on another machine); a dataset folder is read where it is (a path the workers share)."""

    name: str
    kind: str  # kitti, trajectory, route, dataset
    field: str  # where it stands in the spec, for messages
    path: Path | None = None  # the pose file or the dataset
    fmt: str = "auto"
    frames: int | None = None
    route: str | None = None
    times: Path | None = None
    sequence: str | None = None
    detections: Path | None = None
    odometry: Path | None = None
    data: bytes = b""  # the pose file's content
    times_data: bytes | None = None
    content: str = ""  # hash of everything above that the dataset depends on

    @property
    def simulated(self) -> bool:
        return self.kind != "dataset"

    def inputs(self) -> list[Path]:
        return [p for p in (self.path, self.times, self.detections, self.odometry) if p is not None]


@dataclass(frozen=True)
class Setting:
    """The checked config that the cells of one (noise, detector, override) share; `seeded`: each cell puts its own
    seed into `simulator.seed` (the override does not set it)."""

    values: dict[str, Any] = field(repr=False)  # the merged settings, before a cell's seed
    config_json: str = field(repr=False)  # canonical JSON of the resolved config, the seed as _SEED_TOKEN
    simulation_json: str = field(repr=False)  # the same without the run-only sections
    seeded: bool

    def config(self, seed: int | None) -> NeoSLAMConfig:
        if not self.seeded:
            return NeoSLAMConfig.model_validate(self.values)
        return NeoSLAMConfig.model_validate(merge_settings(self.values, {"simulator": {"seed": seed}}))


@dataclass(frozen=True, slots=True)
class Cell:
    index: int  # position in the spec's order: the table's row order
    id: str
    source: str
    noise: str | None
    detector: str | None
    seed: int | None
    override: str
    setting: Setting = field(repr=False, compare=False)
    simulation: str | None  # cells with one key drive one simulated dataset

    @property
    def config(self) -> NeoSLAMConfig:
        """The cell's resolved config (checked when the spec was expanded)."""
        return self.setting.config(self.seed)

    def labels(self) -> dict[str, Any]:
        return {"source": self.source, "noise": self.noise, "detector": self.detector, "seed": self.seed,
                "override": self.override}  # fmt: skip


@dataclass(frozen=True)
class Plan:
    spec: Spec
    cells: list[Cell]
    sources: dict[str, Source]
    code_version: str
    measure: str
    inputs: list[Path]  # every file or folder the sweep reads (an output must not replace them)


def _file_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _fingerprint(path: Path, sequence: str | None) -> str:
    """A dataset folder (or bag file) by its files' names, sizes and modification times: hashing gigabytes of
    images before every sweep would cost more than most cells."""
    roots = [path]
    if sequence is not None and (path / "sequences" / sequence).is_dir():
        roots = [path / "sequences" / sequence, path / "poses" / f"{sequence}.txt"]
    entries = []
    for root in roots:
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for file in files:
            stat = file.stat()
            entries.append([str(file.relative_to(path)), stat.st_size, stat.st_mtime_ns])
    return content_hash(entries)


def _existing(spec: Spec, value: Path, where: str, kind: str = "file") -> Path:
    """A file the spec names (a dataset: a folder or a file); a pipe or a device is refused, as reading one could
    wait forever."""
    path = spec.path(value)
    if not path.exists():
        raise spec.error(where, f"{kind} not found: {path}")
    if kind == "file" and path.is_dir():
        raise spec.error(where, f"is a folder, not a file: {path}")
    if not (path.is_file() or (kind == "dataset" and path.is_dir())):
        raise spec.error(where, f"not a regular file (a pipe or a device?): {path}")
    return path


def _resolve_sources(spec: Spec) -> dict[str, Source]:
    from neoslam.sim.routes import ROUTES

    sources: dict[str, Source] = {}
    for i, entry in enumerate(spec.sources):
        where = f"sources[{i}]"
        kind = entry.kind
        resolved: list[Source] = []
        if kind in ("kitti", "route"):
            names = getattr(entry, kind)
            for name in [names] if isinstance(names, str) else names:
                if kind == "route":
                    if name not in ROUTES:
                        choices = ", ".join(sorted(ROUTES))
                        raise spec.error(f"{where}.route", f"unknown route {name!r}; built-in routes: {choices}")
                    content = content_hash("route", name, entry.frames)
                    resolved.append(Source(entry.name or name, kind, where, route=name, frames=entry.frames,
                                           content=content))  # fmt: skip
                    continue
                path = spec.resolved_data_root() / "kitti" / "poses" / f"{name}.txt"
                if not path.is_file():
                    raise spec.error(f"{where}.kitti", f"KITTI poses not found: {path} (set data_root or NEOSLAM_DATA)")
                data = path.read_bytes()
                content = content_hash("poses", data, "kitti", None, entry.frames)
                resolved.append(Source(entry.name or name, kind, where, path=path, fmt="kitti", frames=entry.frames,
                                       data=data, content=content))  # fmt: skip
        elif kind == "trajectory":
            path = _existing(spec, entry.trajectory, f"{where}.trajectory")
            times = _existing(spec, entry.times, f"{where}.times") if entry.times is not None else None
            data = path.read_bytes()
            times_data = times.read_bytes() if times is not None else None
            content = content_hash("poses", data, entry.format, times_data, entry.frames)
            resolved.append(Source(entry.name or path.stem, kind, where, path=path, fmt=entry.format,
                                   frames=entry.frames, times=times, data=data, times_data=times_data,
                                   content=content))  # fmt: skip
        else:
            path = _existing(spec, entry.dataset, f"{where}.dataset", "dataset")
            detections = odometry = None
            if entry.detections is not None:
                detections = _existing(spec, entry.detections, f"{where}.detections")
            if entry.odometry is not None:
                odometry = _existing(spec, entry.odometry, f"{where}.odometry")
            content = content_hash(
                "dataset",
                _fingerprint(path, entry.sequence),
                entry.sequence,
                _file_hash(detections) if detections else None,
                _file_hash(odometry) if odometry else None,
            )
            default_name = path.name + (f"-{entry.sequence}" if entry.sequence else "")
            resolved.append(Source(entry.name or default_name, kind, where, path=path, sequence=entry.sequence,
                                   detections=detections, odometry=odometry, content=content))  # fmt: skip
        for source in resolved:
            if source.name in sources:
                raise spec.error(f"{where}", f"a second source named {source.name!r}; give it another `name`")
            sources[source.name] = source
    return sources


def _base_values(spec: Spec, environ: Mapping[str, str] | None) -> dict[str, Any]:
    """The spec's config file under the NEOSLAM_* environment variables, as `--config` reads them (checked)."""
    path = _existing(spec, spec.config, "config") if spec.config is not None else None
    try:
        return config_values(path, environ)
    except NeoSLAMError as error:
        raise spec.error("config" if path is not None else "", str(error)) from None


def _axis_values(noise: str | None, detector: str | None, seed: int | None) -> dict[str, Any]:
    if noise is None:
        return {}
    simulator = {
        "noise_profile": noise,
        "odometry": noise_profile(noise).model_dump(),
        "detection_profile": detector,
        "seed": seed,
    }
    return {"simulator": simulator}


def _check_axes(spec: Spec) -> None:
    for axis, values, lookup in (
        ("noise", spec.noise, noise_profile),
        ("detectors", spec.detectors, detection_profile),
    ):
        for i, value in enumerate(values):
            try:
                lookup(value)
            except ValueError as error:
                raise spec.error(f"{axis}[{i}]", str(error)) from None
    try:
        _SEEDS.validate_python(spec.seeds)
    except ValidationError as error:
        first = error.errors()[0]
        raise spec.error(f"seeds{_where(first['loc'])}", f"{first['msg']} (got {first['input']!r})") from None


def _check_metrics(spec: Spec) -> None:
    """The summary's metrics, against what a run measures (a measure of one's own measures other things)."""
    for i, metric in enumerate(spec.metrics):
        if metric not in KNOWN_METRICS:
            raise spec.error(f"metrics[{i}]", f"unknown metric {metric!r}; known: {', '.join(KNOWN_METRICS)}")


def _listed(values: list[Any], most: int = 10) -> str:
    """A list for a one-line message: a long one (thousands of seeds) shortened."""
    if len(values) <= most:
        return str(values)
    return f"[{', '.join(repr(v) for v in values[:most])}, ... ({len(values)} values)]"


def _check_picks(spec: Spec) -> None:
    if spec.cells is None:
        return
    axes = (("noise", spec.noise), ("detector", spec.detectors), ("seed", spec.seeds))
    allowed = {axis: set(values) for axis, values in axes}
    for i, pick in enumerate(spec.cells):
        for axis, values in axes:
            value = getattr(pick, axis)
            if value is not None and value not in allowed[axis]:
                raise spec.error(f"cells[{i}].{axis}", f"{value!r} is not in the spec's list {_listed(values)}")


def _check_overrides(spec: Spec, base: dict[str, Any]) -> None:
    for name, values in spec.overrides.items():
        try:
            NeoSLAMConfig.model_validate(merge_settings(base, values))
        except ValidationError as error:
            first = error.errors()[0]
            message = first["msg"].removeprefix("Value error, ")
            if first["type"] == "extra_forbidden":
                message = "unknown setting"
            raise spec.error(f"overrides.{name}.{_where(first['loc'])}", message) from None


Pick = tuple[str, str | None, str | None, int | None, str]


def _picks(spec: Spec, sources: dict[str, Source]) -> Iterator[Pick]:
    """(source, noise, detector, seed, override) of each cell, in the spec's order."""
    overrides = list(spec.overrides)
    if spec.cells is None:
        for name, source in sources.items():
            if source.simulated:
                for noise, detector, seed, override in product(spec.noise, spec.detectors, spec.seeds, overrides):
                    yield name, noise, detector, seed, override
            else:
                for override in overrides:
                    yield name, None, None, None, override
        return
    for i, pick in enumerate(spec.cells):
        where = f"cells[{i}]"
        if pick.source not in sources:
            raise spec.error(f"{where}.source", f"no source named {pick.source!r}; sources: {', '.join(sources)}")
        override = pick.override if pick.override is not None else overrides[0]
        if override not in spec.overrides:
            raise spec.error(f"{where}.override", f"no override named {override!r}; overrides: {', '.join(overrides)}")
        if not sources[pick.source].simulated:
            if (pick.noise, pick.detector, pick.seed) != (None, None, None):
                raise spec.error(where, "noise, detector and seed apply to simulated sources, not to a dataset")
            yield pick.source, None, None, None, override
            continue
        noise = pick.noise if pick.noise is not None else spec.noise[0]
        detector = pick.detector if pick.detector is not None else spec.detectors[0]
        seed = pick.seed if pick.seed is not None else spec.seeds[0]
        yield pick.source, noise, detector, seed, override


def _canonical(dump: dict[str, Any], sections: frozenset[str] = frozenset()) -> str:
    """JSON as `content_hash` encodes a dict, without some sections."""
    return json.dumps({k: v for k, v in dump.items() if k not in sections}, sort_keys=True, default=str)


def _setting(spec: Spec, base: dict[str, Any], noise: str | None, detector: str | None, override: str) -> Setting:
    """The checked config of (noise, detector, override), the seed left to each cell unless the override sets it."""
    changes = spec.overrides[override]
    seeded = noise is not None and "seed" not in (changes.get("simulator") or {})
    values = merge_settings(merge_settings(base, _axis_values(noise, detector, spec.seeds[0])), changes)
    try:
        dump = NeoSLAMConfig.model_validate(values).model_dump(mode="json")
    except ValidationError as error:
        first = error.errors()[0]
        where = f"overrides.{override}.{_where(first['loc'])}"
        raise spec.error(where, f"{first['msg']} (with noise {noise}, detector {detector})") from None
    if seeded:
        dump["simulator"]["seed"] = SEED_MARK
    return Setting(values, _canonical(dump), _canonical(dump, RUN_ONLY_SECTIONS), seeded)


CellHashes = tuple[_SeededHash, _SeededHash | None]


def _cell_hashes(source: Source, setting: Setting, version: str, measure: str) -> CellHashes:
    """A cell's id (its inputs, its resolved config, the code version, the measurement) and the key of the simulation
    it drives (its inputs and the config without the run-only sections), each by seed."""
    cell_id = _SeededHash((source.content,), setting.config_json, setting.seeded, (version, measure))
    if not source.simulated:
        return cell_id, None
    return cell_id, _SeededHash((source.content,), setting.simulation_json, setting.seeded, ())


def expand(
    spec: Spec,
    environ: Mapping[str, str] | None = None,
    measure: str = DEFAULT_MEASURE,
) -> Plan:
    """Check everything a cell needs (files, profiles, overrides, seeds, and the summary's metrics when the
    measurement is the default) and list the cells in the spec's order. `measure` names the measurement (part of
    every cell's id); `environ` the NEOSLAM_* variables (default: the process's)."""
    _check_picks(spec)
    _check_axes(spec)
    if measure == DEFAULT_MEASURE:
        _check_metrics(spec)
    sources = _resolve_sources(spec)
    base = _base_values(spec, environ)
    _check_overrides(spec, base)
    version = code_version()
    settings: dict[tuple[str | None, str | None, str], Setting] = {}
    hashes: dict[tuple[str, str | None, str | None, str], CellHashes] = {}
    cells = []
    for index, (name, noise, detector, seed, override) in enumerate(_picks(spec, sources)):
        key = (noise, detector, override)
        if key not in settings:
            settings[key] = _setting(spec, base, noise, detector, override)
        setting = settings[key]
        if (name, *key) not in hashes:
            hashes[name, *key] = _cell_hashes(sources[name], setting, version, measure)
        # Two picks that resolve to one run (an override that restates a default) share its id: it runs once.
        cell_id, simulation = hashes[name, *key]
        shared = simulation(seed)[:ID_LENGTH] if simulation is not None else None
        cells.append(Cell(index, cell_id(seed)[:ID_LENGTH], name, noise, detector, seed, override, setting, shared))
    inputs = [p for s in sources.values() for p in s.inputs()]
    if spec.config is not None:
        inputs.append(spec.path(spec.config))
    return Plan(spec, cells, sources, version, measure, inputs)


def axes_that_vary(cells: list[Cell]) -> list[str]:
    """The axes with more than one value among the cells, but the seed (the summary's default groups: medians
    are taken over seeds)."""
    varying = [axis for axis in AXES if axis != "seed" and len({getattr(c, axis) for c in cells}) > 1]
    return varying or ["source"]
