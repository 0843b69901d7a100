"""The chain of anchors the drift gate judges by: metres of path integration between the cells now and a stored
experience's cells, through the places recalls re-anchored them at."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from neoslam.mapping.cell_lineage import CellLineage


def made_every(metres: list[float]) -> CellLineage:
    """Experiences made one after another, `metres[i]` of travel before experience i, no recall."""
    lineage = CellLineage()
    for travelled in metres:
        lineage.travelled(travelled)
        lineage.made()
    return lineage


@settings(max_examples=100, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.floats(0.0, 100.0), min_size=1, max_size=30), st.floats(0.0, 50.0), st.data())
def test_without_a_recall_the_chain_is_the_travel_since_the_experience_was_made(metres, since, data) -> None:
    lineage = made_every(metres)
    lineage.travelled(since)
    experience = data.draw(st.integers(0, len(metres) - 1))
    assert lineage.chain_metres(experience) == pytest.approx(sum(metres[experience + 1 :]) + since)


def test_a_recall_shortens_the_chain_to_the_recalled_place_and_its_neighbours() -> None:
    lineage = made_every([0.0, 10.0, 10.0, 500.0, 10.0])  # 0, 1, 2 close together; 3 and 4 half a km on
    lineage.anchored(1)
    lineage.travelled(5.0)
    assert lineage.chain_metres(1) == 5.0
    assert lineage.chain_metres(0) == 15.0  # up from 1 to 0
    assert lineage.chain_metres(2) == 15.0  # 2 was derived from 1
    assert lineage.chain_metres(4) == pytest.approx(5.0 + 10.0 + 500.0 + 10.0)


def test_experiences_made_after_a_recall_descend_from_the_recalled_place() -> None:
    lineage = made_every([0.0, 300.0, 300.0])  # 0, then 1 at 300 m, 2 at 600 m
    lineage.anchored(0)  # back at 0
    lineage.travelled(20.0)
    lineage.made()  # 3: 20 m from 0's cells
    lineage.travelled(20.0)
    assert lineage.chain_metres(3) == 20.0
    assert lineage.chain_metres(0) == 40.0
    assert lineage.chain_metres(2) == pytest.approx(40.0 + 600.0)


def test_another_sessions_experiences_have_no_chain_and_a_limit_stops_the_walk() -> None:
    lineage = CellLineage()
    lineage.restored(2)
    lineage.made()  # 2: this session's first
    lineage.travelled(100.0)
    lineage.made()  # 3
    assert lineage.chain_metres(0) == math.inf
    assert lineage.chain_metres(2) == 100.0
    assert lineage.chain_metres(2, limit=50.0) == math.inf
    lineage.anchored(1)  # relocalised at a stored experience
    assert lineage.chain_metres(3) == math.inf and lineage.chain_metres(1) == 0.0
