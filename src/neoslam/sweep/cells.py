"""A spec expanded into cells, each with a stable id: the hash of its inputs' content, its resolved config, the code
version and the measurement. Cells that drive the same simulated dataset share a simulation key."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from itertools import product
from pathlib import Path
from typing import Any

from pydantic import ValidationError

import neoslam
from neoslam.config import MAP_SECTIONS, NeoSLAMConfig, config_values, merge_settings
from neoslam.config.calibration import detection_profile, noise_profile
from neoslam.errors import NeoSLAMError
from neoslam.sweep.spec import AXES, Spec, _where

__all__ = ["Source", "Cell", "Plan", "expand", "code_version", "content_hash"]

# Config sections that only the run reads: a simulation is shared by cells that differ in these alone.
RUN_ONLY_SECTIONS = frozenset({"perception", *MAP_SECTIONS, "evaluation"})
ID_LENGTH = 16


def content_hash(*parts: Any) -> str:
    """sha256 of the canonical JSON of the parts (bytes hashed as they are)."""
    digest = hashlib.sha256()
    for part in parts:
        data = part if isinstance(part, bytes) else json.dumps(part, sort_keys=True, default=str).encode()
        digest.update(len(data).to_bytes(8, "little"))
        digest.update(data)
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
class Cell:
    index: int  # position in the spec's order: the table's row order
    id: str
    source: str
    noise: str | None
    detector: str | None
    seed: int | None
    override: str
    config: NeoSLAMConfig = field(repr=False, compare=False)
    simulation: str | None  # cells with one key drive one simulated dataset

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
    path = spec.path(value)
    if not (path.is_file() if kind == "file" else path.exists()):
        raise spec.error(where, f"{kind} not found: {path}")
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


def _picks(spec: Spec, sources: dict[str, Source]) -> list[tuple[str, str | None, str | None, int | None, str]]:
    """(source, noise, detector, seed, override) of each cell, in the spec's order."""
    overrides = list(spec.overrides)
    if spec.cells is None:
        picks = []
        for name, source in sources.items():
            if source.simulated:
                axes = product(spec.noise, spec.detectors, spec.seeds, overrides)
                picks += [(name, n, d, s, o) for n, d, s, o in axes]
            else:
                picks += [(name, None, None, None, o) for o in overrides]
        return picks
    picks = []
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
            picks.append((pick.source, None, None, None, override))
            continue
        noise = pick.noise if pick.noise is not None else spec.noise[0]
        detector = pick.detector if pick.detector is not None else spec.detectors[0]
        seed = pick.seed if pick.seed is not None else spec.seeds[0]
        picks.append((pick.source, noise, detector, seed, override))
    return picks


def _config_hash(config: NeoSLAMConfig, sections: frozenset[str] = frozenset()) -> dict[str, Any]:
    return {k: v for k, v in config.model_dump(mode="json").items() if k not in sections}


def expand(
    spec: Spec,
    environ: Mapping[str, str] | None = None,
    measure: str = "neoslam.commands.run.run_dataset",
) -> Plan:
    """Check everything a cell needs (files, profiles, overrides) and list the cells in the spec's order.
    `measure` names the measurement (part of every cell's id); `environ` the NEOSLAM_* variables (default: the
    process's)."""
    if spec.cells is not None:
        for i, pick in enumerate(spec.cells):
            for axis, value, values in (("noise", pick.noise, spec.noise), ("detector", pick.detector,
                                        spec.detectors), ("seed", pick.seed, spec.seeds)):  # fmt: skip
                if value is not None and value not in values:
                    raise spec.error(f"cells[{i}].{axis}", f"{value!r} is not in the spec's list {values}")
    _check_axes(spec)
    sources = _resolve_sources(spec)
    base = _base_values(spec, environ)
    _check_overrides(spec, base)
    version = code_version()
    cells = []
    for index, (name, noise, detector, seed, override) in enumerate(_picks(spec, sources)):
        source = sources[name]
        values = merge_settings(merge_settings(base, _axis_values(noise, detector, seed)), spec.overrides[override])
        try:
            config = NeoSLAMConfig.model_validate(values)
        except ValidationError as error:
            first = error.errors()[0]
            where = f"overrides.{override}.{_where(first['loc'])}"
            raise spec.error(where, f"{first['msg']} (with noise {noise}, detector {detector})") from None
        full = _config_hash(config)
        # Two picks that resolve to one run (an override that restates a default) share its id: it runs once.
        cell_id = content_hash(source.content, full, version, measure)[:ID_LENGTH]
        simulation = None
        if source.simulated:
            simulation = content_hash(source.content, _config_hash(config, RUN_ONLY_SECTIONS))[:ID_LENGTH]
        cells.append(Cell(index, cell_id, name, noise, detector, seed, override, config, simulation))
    inputs = [p for s in sources.values() for p in s.inputs()]
    if spec.config is not None:
        inputs.append(spec.path(spec.config))
    return Plan(spec, cells, sources, version, measure, inputs)


def axes_that_vary(cells: list[Cell]) -> list[str]:
    """The axes with more than one value among the cells, but the seed (the summary's default groups: medians
    are taken over seeds)."""
    varying = [axis for axis in AXES if axis != "seed" and len({c.labels()[axis] for c in cells}) > 1]
    return varying or ["source"]
