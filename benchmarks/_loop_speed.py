"""Part (b) of benchmarks.loops: the loop query's time against the number of stored keyframes.

The map is laid from the drives' keyframes, each drive in a world of its own far from the others, and again from the
first when all are laid: on the `distinct` map each copy after the first has its objects moved by a smooth random
field of its own (`displaced`: a few metres, alike for objects a few metres apart), so that it is one consistent world
but another layout, as a map of 20,000 keyframes of different streets would be; on the `repeated` map the copies are
exact, every place stored about ten times over (each revisit verifies in every copy: the worst case of a repeated
layout). Every row (a map, a map size and a scope, and the exact eigenvector at the largest size) has its own
detector; the rows' queries are timed in turn, one query of each row after another, so that a machine busy for a while
slows every row alike and the rows compare as a ratio within one run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from neoslam.config import MatchingConfig, load_config
from neoslam.loop.detector import LoopClosureDetector
from neoslam.types import Keyframe

__all__ = ["query_speed", "tiled", "displaced", "MAP_SIZES", "QUICK_MAP_SIZES", "QUERIES"]

MAP_SIZES = [100, 1000, 5000, 20000]
QUICK_MAP_SIZES = [100, 1000, 5000]
QUERIES = 200
TILE_OFFSET_M = 1500.0  # the drives are laid this far apart
EXACT_EIGENVECTOR = {"power_iterations": 100, "power_tolerance": 1e-9}  # the power iteration run to convergence
WHOLE_MAP_M = 1e7  # a search radius that takes every stored keyframe
FIELD_WAVES = 4  # plane waves summed into a copy's displacement field
FIELD_SHIFT_M = 4.0  # RMS displacement of an object, m: past the matching's tolerances (e_max 1.5 m)
FIELD_WAVELENGTH_M = (30.0, 60.0)  # objects metres apart move nearly alike; a street's layout changes
FIELD_SEED = 1000  # a copy's field is drawn from this plus its number


def displaced(centers: np.ndarray, copy: int) -> np.ndarray:
    """Object centres (n, 3) moved in the ground plane by copy `copy`'s smooth random field: FIELD_WAVES plane
    waves of random direction, wavelength and phase, FIELD_SHIFT_M RMS. Estimates of one object in neighbouring
    keyframes (centimetres to decimetres apart) move alike, so that the copy is one consistent world."""
    rng = np.random.default_rng(FIELD_SEED + copy)
    direction = rng.uniform(0.0, 2.0 * np.pi, FIELD_WAVES)
    wavelength = rng.uniform(*FIELD_WAVELENGTH_M, FIELD_WAVES)
    phase = rng.uniform(0.0, 2.0 * np.pi, (FIELD_WAVES, 2))
    wave = (2.0 * np.pi / wavelength)[:, None] * np.column_stack([np.cos(direction), np.sin(direction)])
    argument = centers[:, :2] @ wave.T  # (n, waves)
    shift = np.column_stack([np.cos(argument + phase[:, 0]).sum(1), np.sin(argument + phase[:, 1]).sum(1)])
    moved = np.array(centers, dtype=float)
    moved[:, :2] += FIELD_SHIFT_M / np.sqrt(FIELD_WAVES) * shift
    return moved


def tiled(drives: list[list[Keyframe]], size: int, distinct: bool = True) -> list[tuple[Keyframe, float]]:
    """`size` keyframes from the drives' keyframes, each drive (in turn, again from the first when all are laid)
    shifted far from the others, with odometer readings as if driven one after another; `distinct`: every copy
    after the drives' first has its objects `displaced` by a field of its own."""
    spacing = 5.0
    laid: list[tuple[Keyframe, float]] = []
    copy = 0
    while len(laid) < size:
        shift = np.eye(4)
        shift[:2, 3] = [TILE_OFFSET_M * (copy % 8), TILE_OFFSET_M * (copy // 8)]
        for k in drives[copy % len(drives)][: size - len(laid)]:
            if distinct and copy >= len(drives):
                k = replace(k, centers=displaced(k.centers, copy))
            laid.append((replace(k.moved(shift), id=len(laid)), spacing * len(laid)))
        copy += 1
    return laid


def _scrambled(keyframe: Keyframe, rng: np.random.Generator) -> Keyframe:
    """The same objects at the same place, each moved a random 3-10 m: a layout that is nowhere in the map."""
    angle = rng.uniform(0, 2 * np.pi, len(keyframe.labels))
    radius = rng.uniform(3.0, 10.0, len(keyframe.labels))
    moved = keyframe.centers + np.column_stack([radius * np.cos(angle), radius * np.sin(angle), 0 * angle])
    return replace(keyframe, centers=moved)


@dataclass
class _Row:
    """One row of the table: its detector over the first `size` keyframes of the stream, its queries (a revisit of
    a random stored keyframe and a new place made from it, in turn: the same for every row of one size) and their
    times."""

    layout: str
    eigenvector: str
    scope: str
    size: int
    detector: LoopClosureDetector
    queries: list[tuple[str, Keyframe]]
    odometer: float
    eligible: list[int]
    times: dict[str, list[float]] = field(default_factory=lambda: {"revisit": [], "new": []})


def _row(
    layout: str,
    eigenvector: str,
    matching: MatchingConfig,
    stream: list[tuple[Keyframe, float]],
    size: int,
    queries: int,
    scope: str,
) -> _Row:
    """A row's detector and queries on the map `layout` ("distinct" or "repeated", the stream laid so); `scope`
    "drift-bounded" (the search radius round the estimate) or "whole map" (every stored keyframe a candidate, as a
    later session or a lost robot searches)."""
    config = load_config(environ={})
    if scope == "whole map":
        matching = matching.model_copy(update={"search_radius": WHOLE_MAP_M})
    detector = LoopClosureDetector(config.keyframes, matching)
    for keyframe, odometer in stream[:size]:
        detector.add(keyframe, odometer)
    odometer_now = stream[size - 1][1] + matching.exclude_recent_distance + 1.0
    rng = np.random.default_rng(size)
    chosen, eligible = [], []
    for index in rng.integers(0, size, queries):
        keyframe = stream[int(index)][0]
        chosen += [("revisit", keyframe), ("new", _scrambled(keyframe, rng))]
        eligible.append(len(detector.index.eligible(keyframe.pose[:3, 3], odometer_now)))
    return _Row(layout, eigenvector, scope, size, detector, chosen, odometer_now, eligible)


def _measured(row: _Row) -> dict:
    """The row's medians (ms) and memory: the retrieval index, the stored keyframes, the places cached after its
    queries."""
    times = row.times["revisit"] + row.times["new"]
    return {
        "map": row.layout,
        "eigenvector": row.eigenvector,
        "scope": row.scope,
        "map_size": row.size,
        "queries": len(row.times["revisit"]),
        "eligible_median": int(np.median(row.eligible)),
        "revisit_ms_median": 1e3 * float(np.median(row.times["revisit"])),
        "new_place_ms_median": 1e3 * float(np.median(row.times["new"])),
        "query_ms_median": 1e3 * float(np.median(times)),
        "query_ms_p95": 1e3 * float(np.percentile(times, 95)),
        "index_mb": row.detector.index.nbytes / 1e6,
        "keyframes_mb": sum(k.nbytes for k in row.detector.index.keyframes) / 1e6,
        "places_mb": row.detector.places.nbytes / 1e6,
    }


def query_speed(drives: list[list[Keyframe]], sizes: list[int], queries: int) -> list[dict]:
    """On the distinct map, a row per map size and scope with the default matching, then one at the largest size
    with the exact eigenvector; on the repeated map, a row per scope at the largest size; their queries timed in
    turn (module docstring). A revisit, like a new place, matches every candidate place: the query keeps the one
    with the most evidence."""
    matching = load_config(environ={}).matching
    largest = max(sizes)
    stream, repeated = tiled(drives, largest), tiled(drives, largest, distinct=False)
    scopes = ("drift-bounded", "whole map")
    rows = [_row("distinct", "default", matching, stream, size, queries, scope) for scope in scopes for size in sizes]
    exact = matching.model_copy(update=EXACT_EIGENVECTOR)
    rows.append(_row("distinct", "exact", exact, stream, largest, queries, "drift-bounded"))
    rows += [_row("repeated", "default", matching, repeated, largest, queries, scope) for scope in scopes]
    for turn in range(2 * queries):
        for row in rows:
            kind, query = row.queries[turn]
            start = time.perf_counter()
            row.detector.relocalise(query, row.odometer)
            row.times[kind].append(time.perf_counter() - start)
    return [_measured(row) for row in rows]
