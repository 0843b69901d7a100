"""A run killed (SIGKILL) at any moment, while it opens, commits to or closes its map, leaves a file that opens,
passes SQLite's integrity check and holds exactly the map of its last committed transaction."""

from __future__ import annotations

import multiprocessing
import os
import random
import signal
import sqlite3
import tempfile
import time
from pathlib import Path

import pytest

from neoslam.config import NeoSLAMConfig
from neoslam.store.map_file import MapFile
from neoslam.types import MapState

KILLS = 24
SEED = 13


def config_of(round_: int) -> NeoSLAMConfig:
    """Both durability settings: only the map sections must agree between sessions."""
    return NeoSLAMConfig(map_store={"synchronous": "normal" if round_ % 3 else "full"})


def extend(path: Path, config: NeoSLAMConfig, growth, report) -> None:
    """A run that never ends: open the map, commit four more steps, close it, again; each commit's keyframe count
    goes to the parent once the commit has returned."""
    while True:
        with MapFile.open(path, config) as map_file:
            first = len(map_file.load().keyframes) + 1
            for step in range(first, first + 4):
                map_file.commit(growth.state(step))
                report.send(step)


@pytest.mark.slow
def test_killed_runs_leave_every_committed_step(tmp_path, growth, same_state, monkeypatch):
    grow = growth(objects_per_keyframe=4, patch=12, correction_every=2)
    scratch = tmp_path / "scratch"  # where the private copies of a map opened read-only go
    scratch.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    maps = tmp_path / "maps"
    maps.mkdir()
    path = maps / "map.neoslam"
    MapFile.create(path, config_of(0)).close()
    context = multiprocessing.get_context("fork")
    delays = random.Random(SEED)
    reported = 0
    started = time.perf_counter()
    for round_ in range(KILLS):
        receiver, sender = context.Pipe(duplex=False)
        child = context.Process(target=extend, args=(path, config_of(round_), grow, sender), daemon=True)
        child.start()
        sender.close()
        time.sleep(delays.uniform(0.002, 0.12))
        os.kill(child.pid, signal.SIGKILL)
        child.join()
        assert child.exitcode == -signal.SIGKILL
        while True:
            try:
                reported = receiver.recv()
            except EOFError:
                break
        receiver.close()
        read_only = round_ % 2 == 1  # read-only leaves a crashed map's log for the next run to recover
        with MapFile.open(path, config_of(round_ + 1), read_only=read_only) as map_file:
            assert map_file._connection.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
            state = map_file.load()
        steps = len(state.keyframes)
        assert steps >= reported, f"round {round_}: {steps} keyframes after a commit of {reported} was reported"
        expected = grow.state(steps) if steps else MapState()  # nothing committed yet: the empty map
        same_state(state, expected)  # exactly the map of one commit: every part of the same step
        if not read_only:
            assert [p.name for p in maps.iterdir()] == ["map.neoslam"]
            with sqlite3.connect(f"file:{path}?mode=ro", uri=True) as raw:
                assert raw.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
            raw.close()
    assert reported >= KILLS  # the runs got on: most rounds committed something
    assert list(scratch.iterdir()) == []  # copies that killed runs left were swept by the next open
    assert time.perf_counter() - started < 30
