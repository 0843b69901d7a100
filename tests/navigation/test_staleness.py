"""Stale objects: an object passed within view without being seen, by experiences made after its last sighting,
is stale after `stale_after_misses` such passes; one out of view, one seen again, or one in another part of the map
is not."""

from __future__ import annotations

import numpy as np
import pytest
from tests.navigation.streets import MapBuilder

from neoslam.config import NavigationConfig
from neoslam.navigation import NavigationGraph, map_view, object_statuses

VIEW = {"field_of_view_deg": 80.0, "view_min_range": 3.0, "view_range": 20.0}  # the geometry below assumes it
CONFIG = NavigationConfig(stale_after_misses=2, **VIEW)


def _statuses(builder: MapBuilder, config: NavigationConfig = CONFIG):
    view = map_view(builder.state())
    return {o.id: o for o in object_statuses(view, NavigationGraph.build(view, config), config, min_observations=3)}


@pytest.fixture
def street() -> tuple[MapBuilder, list[int]]:
    """A street driven east from (0, 0) to (100, 0), experiences every 5 m; a truck at (50, -5) seen from the two
    experiences before it (40 and 45 m), a car at (50, 40) seen from (45, 0), out of view of the street later."""
    builder = MapBuilder()
    east = builder.drive([(0, 0), (100, 0)])
    builder.add_object("truck", (50, -5, 0.5), {builder.nearest(40, 0): 2, builder.nearest(45, 0): 2})
    builder.add_object("car", (50, 40, 0.5), {builder.nearest(45, 0): 3})
    return builder, east


def test_an_object_passed_twice_in_view_without_being_seen_is_stale(street):
    builder, east = street
    assert not _statuses(builder)[0].stale  # after the sightings, the street went on past it: out of view
    # Session 2 drives the street back west (new experiences, facing the truck as they come) and sees nothing.
    builder.drive([(100, 2), (0, 2)], session=2, after=east[-1])
    truck = _statuses(builder)[0]
    # from (65, 2) and (60, 2) the truck is 16.6 and 12.2 m away, 25 and 35 degrees off the heading: in view; from
    # (70, 2) 21.2 m away (beyond view_range), from (55, 2) 54 degrees off (beyond half the field of view)
    assert truck.misses == 2 and truck.stale
    assert (truck.last_seen_experience, truck.last_seen_session, truck.last_seen_frame) == (9, 1, 90)
    assert truck.sessions == frozenset({1})
    assert "session 1, frame 90 (experience 9)" in truck.last_seen()


def test_one_miss_is_not_enough_and_the_number_is_configurable(street):
    builder, east = street
    builder.drive([(100, 2), (0, 2)], session=2, after=east[-1])
    assert not _statuses(builder, NavigationConfig(stale_after_misses=3, **VIEW))[0].stale
    assert _statuses(builder, NavigationConfig(stale_after_misses=2, **VIEW))[0].stale


def test_an_object_out_of_view_of_the_later_passes_is_not_stale(street):
    builder, east = street
    builder.drive([(100, 2), (0, 2)], session=2, after=east[-1])
    car = _statuses(builder)[1]  # 38 m from the street: beyond view_range
    assert car.misses == 0 and not car.stale
    narrow = NavigationConfig(stale_after_misses=2, **(VIEW | {"field_of_view_deg": 20.0}))  # the truck now to the side
    assert not _statuses(builder, narrow)[0].stale


def test_an_object_seen_again_is_not_stale(street):
    builder, east = street
    back = builder.drive([(100, 2), (0, 2)], session=2, after=east[-1])
    builder.objects[0][2][back[7]] = 3  # seen from (65, 2) on the way back
    truck = _statuses(builder)[0]
    assert truck.last_seen_experience == back[7] and truck.last_seen_session == 2
    assert truck.misses == 1 and not truck.stale  # (60, 2), after the sighting, missed it
    assert truck.sessions == frozenset({1, 2})


def test_experiences_of_another_part_of_the_map_do_not_count(street):
    builder, _ = street
    builder.drive([(100, 2), (0, 2)], session=2)  # never linked: another frame, whatever its coordinates
    assert _statuses(builder)[0].misses == 0


def test_positions_follow_the_corrected_map_and_unconfirmed_objects_are_left_out(street):
    builder, _ = street
    builder.add_object("person", (20, -5, 0.5), {builder.nearest(15, 0): 2})  # seen twice: below 3
    statuses = _statuses(builder)
    assert sorted(statuses) == [0, 1]
    np.testing.assert_allclose(statuses[0].position, [50.0, -5.0, 0.5], atol=1e-9)
    state = builder.state()
    state.experience_poses[:, 1, 3] += 10.0  # the correction moves the whole street 10 m north
    view = map_view(state)
    moved = object_statuses(view, NavigationGraph.build(view, CONFIG), CONFIG, 3)
    np.testing.assert_allclose(moved[0].position, [50.0, 5.0, 0.5], atol=1e-9)
    assert moved[0].describe() == "truck 0" and moved[0].observations == 4
