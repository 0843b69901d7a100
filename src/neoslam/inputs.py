"""Input files: regular files (or folders) only, and no more bytes than their format can need.

A FIFO, a device, a socket or a link to one is refused with one line instead of blocking a reader forever or
reading without end (`/dev/zero`), and every reader reads at most the bound of its format, so that a wrong path
costs an error, never all memory. The bounds (docs/formats.md) are far above what any real input of the format
holds: a KITTI sequence's longest text file is under 1 MB, an image under 1 MB, a detector model under 100 MB.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import BinaryIO

from neoslam.errors import InputError

__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_IMAGE_BYTES",
    "MAX_MODEL_BYTES",
    "MAX_TEXT_BYTES",
    "check_input_file",
    "check_input_folder_files",
    "count_lines",
    "read_input_bytes",
]

MAX_TEXT_BYTES = 256 * 2**20  # a text table, trajectory or detections file (a day's drive of detections: ~50 MB)
MAX_CONFIG_BYTES = 16 * 2**20  # a YAML configuration, sweep spec or dataset description
MAX_IMAGE_BYTES = 64 * 2**20  # one encoded image (a KITTI PNG: ~0.3 MB; an uncompressed 4K image: 25 MB)
MAX_MODEL_BYTES = 2 * 2**30  # an ONNX detector (protobuf's own limit)
_COUNT_BLOCK = 2**20  # bytes read at once when lines are counted

_KINDS = {
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFSOCK: "a socket",
}


def _kind(mode: int) -> str:
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


def _refusal(path: Path, mode: int) -> InputError:
    if stat.S_ISDIR(mode):
        return InputError(path, "is a folder, not a file")
    what = _kind(mode)
    link = f" (a link to {os.path.realpath(path)})" if path.is_symlink() else ""
    return InputError(path, f"is {what}{link}, not a regular file")


def _stat(path: Path, missing: str) -> os.stat_result:
    try:
        return path.stat()
    except FileNotFoundError:
        raise InputError(path, missing) from None
    except OSError as error:
        raise InputError(path, f"cannot be read ({error.strerror})") from None


def _too_large(path: Path, size: int, limit: int) -> InputError:
    return InputError(path, f"is {size:,} bytes; a file of this kind holds at most {limit:,}")


def check_input_file(path: Path, missing: str = "file not found", limit: int | None = None) -> int:
    """The size of a regular input file; InputError when it is missing, not a regular file, or over `limit`."""
    status = _stat(path, missing)
    if not stat.S_ISREG(status.st_mode):
        raise _refusal(path, status.st_mode)
    if limit is not None and status.st_size > limit:
        raise _too_large(path, status.st_size, limit)
    return status.st_size


def check_input_folder_files(folder: Path) -> None:
    """Every entry of an input folder read as a whole (a ROS 2 bag) is a regular file or a folder."""
    for entry in sorted(folder.iterdir()):
        mode = _stat(entry, "vanished while being read").st_mode
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise _refusal(entry, mode)


def _open_regular(path: Path, missing: str) -> tuple[BinaryIO, int]:
    """The file opened for reading without blocking, checked again once open (a path swapped for a FIFO after the
    check cannot hang a read)."""
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise InputError(path, missing) from None
    except OSError as error:
        if error.errno == errno.EISDIR:
            raise InputError(path, "is a folder, not a file") from None
        raise InputError(path, f"cannot be read ({error.strerror})") from None
    handle = os.fdopen(descriptor, "rb")
    status = os.fstat(handle.fileno())
    if not stat.S_ISREG(status.st_mode):
        handle.close()
        raise _refusal(path, status.st_mode)
    return handle, status.st_size


def read_input_bytes(path: Path, missing: str = "file not found", limit: int = MAX_TEXT_BYTES) -> bytes:
    """A regular file's bytes, at most `limit` of them. The file is opened without blocking and checked again
    once open, so that a path swapped for a FIFO after the check cannot hang the read."""
    check_input_file(path, missing, limit)
    handle, size = _open_regular(path, missing)
    with handle:
        try:
            # Sized by the file, not the limit: a read of limit + 1 bytes allocates that much at once.
            data = handle.read(min(limit, size) + 1)
            if len(data) > size:  # the file grew since: read on, up to the limit
                data += handle.read(limit + 1 - len(data))
        except OSError as error:
            raise InputError(path, f"cannot be read ({error.strerror})") from None
    if len(data) > limit:
        raise _too_large(path, len(data), limit)
    return data


def count_lines(path: Path, missing: str = "file not found", limit: int = MAX_TEXT_BYTES) -> int:
    """The number of lines of a regular text file of at most `limit` bytes, read a block at a time (what reading
    it whole will cost can be known before it is read)."""
    check_input_file(path, missing, limit)
    handle, _ = _open_regular(path, missing)
    lines, read, last = 0, 0, b"\n"
    with handle:
        try:
            while block := handle.read(_COUNT_BLOCK):
                lines, read, last = lines + block.count(b"\n"), read + len(block), block[-1:]
                if read > limit:
                    raise _too_large(path, read, limit)
        except OSError as error:
            raise InputError(path, f"cannot be read ({error.strerror})") from None
    return lines + (last != b"\n")
