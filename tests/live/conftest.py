"""The live node's tests talk DDS on this machine only: each gets a ROS domain of its own (so that tests, and
anything else on the machine, never hear each other) and Cyclone DDS kept to the loopback interface."""

from __future__ import annotations

import itertools
import os

import pytest
from tests.conftest import require_extra

LOOPBACK = (
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo"/></Interfaces>'
    "</General></Domain></CycloneDDS>"
)
# Domains 120-219, by process and test: Cyclone maps a domain to UDP ports 7400 + 250 x id, and ids above 232
# would leave the port range.
FIRST_DOMAIN, DOMAINS = 120, 100
_numbers = itertools.count()


@pytest.fixture(scope="session", autouse=True)
def _cyclone_on_loopback() -> None:
    require_extra("cyclonedds", "ros2")
    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK)


@pytest.fixture
def domain_id() -> int:
    """A ROS domain id no other test of this session uses at the same time."""
    return FIRST_DOMAIN + (os.getpid() * 7 + next(_numbers)) % DOMAINS
