"""The memory a command may plan to use, and the refusal of work that would exceed it before it starts.

The budget is `NEOSLAM_MAX_MEMORY` (bytes, or with a K, M or G suffix: `8G`), by default a quarter of the machine's
memory. Work whose cost its configuration or an input's header gives (a simulation's appearance patches, an
image's pixels, the lines of the trajectories `evaluate` reads) is checked against it first: one line naming what
would exceed it, nothing allocated.
"""

from __future__ import annotations

import os
import re

from neoslam.errors import ConfigError

__all__ = ["DEFAULT_SHARE", "budget_bytes", "check_budget", "describe_bytes"]

DEFAULT_SHARE = 0.25  # of the machine's memory, when NEOSLAM_MAX_MEMORY is not set
_FALLBACK_BYTES = 4 * 2**30  # where the machine's memory cannot be read
_UNITS = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
_AMOUNT = re.compile(r"^\s*(\d+(?:\.\d+)?)\s*([KMGT]?)i?B?\s*$", re.IGNORECASE)


def budget_bytes() -> int:
    """NEOSLAM_MAX_MEMORY in bytes, or DEFAULT_SHARE of the machine's memory; ConfigError for a value that is not
    an amount."""
    given = os.environ.get("NEOSLAM_MAX_MEMORY")
    if given:
        match = _AMOUNT.match(given)
        if match is None or float(match.group(1)) <= 0:
            shown = given if len(given) <= 40 else f"{given[:37]}..."
            raise ConfigError(f"NEOSLAM_MAX_MEMORY: {shown!r} is not an amount of memory (bytes, or 512M, 8G)")
        return int(float(match.group(1)) * _UNITS[match.group(2).upper()])
    try:
        memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return _FALLBACK_BYTES
    return int(memory * DEFAULT_SHARE) if memory > 0 else _FALLBACK_BYTES


def describe_bytes(count: float) -> str:
    for unit, size in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if count >= size:
            return f"{count / size:.1f} {unit}"
    return f"{int(count)} bytes"


def check_budget(what: str, needed: float) -> None:
    """Refuse (ConfigError) work that needs more than the budget: `what` says what it is and from what."""
    budget = budget_bytes()
    if needed > budget:
        raise ConfigError(
            f"{what} need at least {describe_bytes(needed)}, more than the memory budget of {describe_bytes(budget)} "
            "(NEOSLAM_MAX_MEMORY; by default a quarter of this machine's memory)"
        )
