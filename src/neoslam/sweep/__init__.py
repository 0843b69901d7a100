"""Sweeps: a grid (or list) of drives x noise profiles x detection profiles x seeds x config overrides, each cell
run, evaluated and kept, on a local process pool or a Ray cluster, resumable, into one table (`neoslam sweep`).

```python
from neoslam.sweep import load_spec, run_sweep

result = run_sweep(load_spec(Path("sweep.yaml")), Path("out"))   # local pool, one worker per core
print(result.summary)                                              # also out/summary.md; rows: out/sweep.csv
```
"""

from neoslam.sweep.cells import Cell, Plan, Source, code_version, expand
from neoslam.sweep.driver import CellRecord, SweepResult, run_sweep
from neoslam.sweep.executors import Executor, InProcess, LocalPool, RayCluster, make_executor
from neoslam.sweep.spec import Spec, SpecError, load_spec, parse_spec

__all__ = [
    "Spec",
    "SpecError",
    "load_spec",
    "parse_spec",
    "Cell",
    "Plan",
    "Source",
    "expand",
    "code_version",
    "CellRecord",
    "SweepResult",
    "run_sweep",
    "Executor",
    "LocalPool",
    "InProcess",
    "RayCluster",
    "make_executor",
]
