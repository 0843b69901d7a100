"""NeoSLAM: Neural Object SLAM (brain-inspired object SLAM).

The Python API for driving NeoSLAM from another program, frame by frame:

```python
from neoslam import Frame, NeoSLAM, ObjectObservation, load_config

slam = NeoSLAM(load_config())          # or NeoSLAMConfig(...), or load_config(Path("my.yaml"))
pose = slam.step(Frame(...))           # T_world_robot after this frame
result = slam.result(frame_times_s)    # trajectories, object map, keyframes, loop closures, experience map
```

The names (and `__version__`) are looked up on first use, so that `import neoslam` (and the CLI's start, whose
signal handling comes first) stays fast.
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from neoslam.config import NeoSLAMConfig, load_config
    from neoslam.pipeline import NeoSLAM, RunResult, run
    from neoslam.types import Frame, ObjectObservation, Trajectory

# Public name -> the module defining it.
_PUBLIC = {
    "NeoSLAM": "neoslam.pipeline",
    "RunResult": "neoslam.pipeline",
    "run": "neoslam.pipeline",
    "Frame": "neoslam.types",
    "ObjectObservation": "neoslam.types",
    "Trajectory": "neoslam.types",
    "NeoSLAMConfig": "neoslam.config",
    "load_config": "neoslam.config",
}

__all__ = [
    "__version__",
    "NeoSLAM",
    "RunResult",
    "run",
    "Frame",
    "ObjectObservation",
    "Trajectory",
    "NeoSLAMConfig",
    "load_config",
]


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("neoslam")
    except PackageNotFoundError:  # running from a source tree that was not installed
        return "0.0.0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        return _version()
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'neoslam' has no attribute {name!r}")
