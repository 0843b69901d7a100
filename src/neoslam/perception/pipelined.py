"""The front end's stages overlapped: while frame k is tracked by the odometry, frame k+1 is placed in 3-D, frame
k+2 detected and the frames after them read and decoded, each stage in a thread of its own with a bounded queue
between stages.

Every stage still takes the frames one at a time and in order, so the frames that come out are the same, byte for
byte, as those of the sequential front end; only the wall time differs (onnxruntime's inference and OpenCV's
decoding, ORB and optical flow release the GIL). An error in a stage reaches the consumer at the frame where it
happened; stopping the consumer (closing the generator) stops the stages.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any

__all__ = ["staged"]

_POLL_S = 0.1  # how often a blocked stage looks whether the consumer has gone: stops within this


@dataclass(frozen=True, slots=True)
class _Failed:
    error: BaseException


_DONE = object()


def _put(out: queue.Queue, item: Any, stop: threading.Event) -> bool:
    """Put `item` unless the consumer has gone; False then."""
    while not stop.is_set():
        try:
            out.put(item, timeout=_POLL_S)
            return True
        except queue.Full:
            continue
    return False


def _get(source: queue.Queue, stop: threading.Event) -> Any:
    while not stop.is_set():
        try:
            return source.get(timeout=_POLL_S)
        except queue.Empty:
            continue
    return _DONE


def _feed(items: Iterable[Any], out: queue.Queue, stop: threading.Event) -> None:
    try:
        for item in items:
            if not _put(out, item, stop):
                return
    except BaseException as error:  # noqa: BLE001 - handed to the consumer at this point of the sequence
        _put(out, _Failed(error), stop)
        return
    _put(out, _DONE, stop)


def _work(work: Callable[[Any], Any], source: queue.Queue, out: queue.Queue, stop: threading.Event) -> None:
    while True:
        item = _get(source, stop)
        if item is _DONE or isinstance(item, _Failed):
            _put(out, item, stop)
            return
        try:
            result = work(item)
        except BaseException as error:  # noqa: BLE001 - handed to the consumer at this point of the sequence
            _put(out, _Failed(error), stop)
            return
        if not _put(out, result, stop):
            return


def staged(items: Iterable[Any], stages: list[Callable[[Any], Any]], depth: int) -> Iterator[Any]:
    """`items` through each of `stages` in turn, each stage (and the iteration of `items`) in its own thread, at
    most `depth` items waiting between two stages; yields the last stage's results in the items' order."""
    stop = threading.Event()
    queues = [queue.Queue(maxsize=depth) for _ in range(len(stages) + 1)]
    threads = [threading.Thread(target=_feed, args=(items, queues[0], stop), daemon=True, name="frames")]
    for k, work in enumerate(stages):
        args = (work, queues[k], queues[k + 1], stop)
        threads.append(threading.Thread(target=_work, args=args, daemon=True, name=f"stage-{k}"))
    for thread in threads:
        thread.start()
    try:
        while True:
            item = _get(queues[-1], stop)
            if item is _DONE:
                return
            if isinstance(item, _Failed):
                raise item.error
            yield item
    finally:
        stop.set()
        deadline = time.monotonic() + 2 * _POLL_S
        for thread in threads:
            thread.join(max(0.0, deadline - time.monotonic()))
