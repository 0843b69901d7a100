"""A run as one session of a map file: the file is opened (or created) before the run, committed after every
step that made a keyframe or closed a loop, and once more at the end, so that a run killed at any moment leaves
every keyframe up to its last step with one in the file."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from neoslam.config import NeoSLAMConfig
from neoslam.errors import InputError, OutputError
from neoslam.io.atomic import check_target_file
from neoslam.store.map_file import MapFile
from neoslam.types import Frame, MapState

__all__ = ["MapRecorder", "MapRecording", "check_map_path", "map_recording"]


def check_map_path(path: Path, out: Path | None, inputs: Iterable[Path | None], localise_only: bool) -> None:
    """Refuse a map path before any work: a link, a folder, one of the run's inputs (or inside or holding one), a
    path inside the results folder `out` (which a run replaces whole; None: no results folder), or, with
    `localise_only`, a missing map."""
    check_target_file(path, overwrite=True, inputs=inputs)
    resolved = path.resolve()
    if out is not None and (resolved == out.resolve() or out.resolve() in resolved.parents):
        raise OutputError(f"{path}: lies inside the results folder {out}, which a run replaces whole; keep it outside")
    if not path.exists():
        if localise_only:
            raise InputError(path, "map not found (--localise-only uses an existing map)")
        if not path.parent.is_dir():
            raise InputError(path.parent, "folder not found (for the new map file)")


class MapRecorder:
    """The run's step observer that commits the map: after each step that made a keyframe (stored or recognised)
    or accepted a closure; `finish` commits the final map (after the run's last optimisation)."""

    def __init__(self, map_file: MapFile | None) -> None:
        self.map_file = map_file  # None: --localise-only, nothing is written
        self._slam = None
        self._seen = (0, 0)

    def __call__(self, slam, frame: Frame, pose) -> None:
        self._slam = slam
        marker = (len(slam.keyframes.frames), len(slam.loop_closures))
        if self.map_file is not None and marker != self._seen:
            self._seen = marker
            self.map_file.commit(slam.map_state())

    def finish(self) -> None:
        if self.map_file is not None and self._slam is not None:
            self.map_file.commit(self._slam.map_state())


@dataclass
class MapRecording:
    """The map a run starts from (empty for a new file) and the observer that writes it."""

    path: Path
    stored: MapState
    recorder: MapRecorder
    localise_only: bool


@contextmanager
def map_recording(path: Path, config: NeoSLAMConfig, localise_only: bool) -> Iterator[MapRecording]:
    """Open a map file (checked; read-only with `localise_only`) or create it, for one run."""
    exists = path.exists()
    map_file = MapFile.open(path, config, read_only=localise_only) if exists else MapFile.create(path, config)
    try:
        stored = map_file.load()
        yield MapRecording(path, stored, MapRecorder(None if localise_only else map_file), localise_only)
    finally:
        map_file.close()
