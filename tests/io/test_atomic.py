"""Output folders appear whole or not at all."""

from __future__ import annotations

import os
import shutil
import signal
from pathlib import Path

import pytest

from neoslam.errors import OutputError
from neoslam.io import atomic
from neoslam.io.atomic import atomic_directory


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if "partial" in p.name)


def test_writes_a_new_folder(tmp_path: Path) -> None:
    target = tmp_path / "nested" / "out"
    with atomic_directory(target) as staging:
        assert staging != target
        assert not target.exists()  # nothing visible until the body is done
        (staging / "a.txt").write_text("a")
    assert (target / "a.txt").read_text() == "a"
    assert _leftovers(target.parent) == []


def test_an_empty_existing_folder_is_used(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.mkdir()
    with atomic_directory(target) as staging:
        (staging / "a.txt").write_text("a")
    assert sorted(p.name for p in target.iterdir()) == ["a.txt"]


def test_refuses_a_non_empty_folder_without_overwrite(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "old.txt").write_text("old")
    with pytest.raises(OutputError, match="not empty"), atomic_directory(target):
        pytest.fail("the body must not run")
    assert (target / "old.txt").read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_overwrite_replaces_the_folder(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "old.txt").write_text("old")
    with atomic_directory(target, overwrite=True) as staging:
        (staging / "new.txt").write_text("new")
        assert (target / "old.txt").exists()  # the old results stay until the new ones are complete
    assert sorted(p.name for p in target.iterdir()) == ["new.txt"]
    assert _leftovers(tmp_path) == []


def test_refuses_a_file(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.write_text("x")
    with pytest.raises(OutputError, match="not a folder"), atomic_directory(target, overwrite=True):
        pass
    assert target.read_text() == "x"


def test_failure_leaves_nothing_behind(tmp_path: Path) -> None:
    target = tmp_path / "out"
    with pytest.raises(RuntimeError, match="boom"), atomic_directory(target) as staging:
        (staging / "half.txt").write_text("half")
        raise RuntimeError("boom")
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_failure_with_overwrite_keeps_the_old_folder(tmp_path: Path) -> None:
    target = tmp_path / "out"
    target.mkdir()
    (target / "old.txt").write_text("old")
    with pytest.raises(KeyboardInterrupt), atomic_directory(target, overwrite=True) as staging:
        (staging / "half.txt").write_text("half")
        raise KeyboardInterrupt
    assert sorted(p.name for p in target.iterdir()) == ["old.txt"]
    assert _leftovers(tmp_path) == []


def test_a_second_interrupt_during_clean_up_waits_for_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A second Ctrl-C while the first one's clean-up removes the staging folder: the folder still goes."""
    remove = shutil.rmtree

    def interrupted_rmtree(path, **options) -> None:
        os.kill(os.getpid(), signal.SIGINT)  # Python runs the handler at the next bytecode: inside the removal
        remove(path, **options)

    with pytest.raises(KeyboardInterrupt), atomic_directory(tmp_path / "out") as staging:
        (staging / "part.txt").write_text("half")
        monkeypatch.setattr(atomic.shutil, "rmtree", interrupted_rmtree)  # the clean-up's removal, not the set-up's
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
