"""The goal language: every form reads into its typed goal, its canonical text reads back to the same goal, and
what is not a goal is one GoalError naming it."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from neoslam.errors import GoalError
from neoslam.navigation import (
    ExperienceGoal,
    KeyframeGoal,
    ObjectGoal,
    ObjectQuery,
    PointGoal,
    StartGoal,
    parse_goal,
)

READINGS = {
    "experience 40": ExperienceGoal(40),
    "  Experience   40 ": ExperienceGoal(40),
    "keyframe 7": KeyframeGoal(7),
    "object 12": ObjectGoal(12),
    "stale object 12": ObjectGoal(12, stale=True),
    "12.5,-3": PointGoal(12.5, -3.0),
    "12.5, -3, 1.2": PointGoal(12.5, -3.0, 1.2),
    "x=12.5 y=-3": PointGoal(12.5, -3.0),
    "x = 1e2, y = .5 z=-2": PointGoal(100.0, 0.5, -2.0),
    "start": StartGoal(),
    "start of session 2": StartGoal(2),
    "truck": ObjectQuery("truck"),
    "nearest truck": ObjectQuery("truck"),
    "a car": ObjectQuery("car"),
    "The Truck": ObjectQuery("truck", unique=True),
    "car seen 3+ times": ObjectQuery("car", min_observations=3),
    "car seen at least 3 times": ObjectQuery("car", min_observations=3),
    "car in session 2": ObjectQuery("car", session=2),
    "nearest car in session 2 seen 4+ times": ObjectQuery("car", min_observations=4, session=2),
    "stale truck": ObjectQuery("truck", stale=True),
    "the stale traffic light": ObjectQuery("traffic light", unique=True, stale=True),
}


@pytest.mark.parametrize("text", READINGS)
def test_each_form_reads_into_its_goal_and_back(text):
    goal = parse_goal(text)
    assert goal == READINGS[text]
    assert parse_goal(goal.describe()) == goal


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("", "empty goal"),
        ("   ", "empty goal"),
        ("experience", "not a goal"),
        ("object", "not a goal"),
        ("12,", "not a goal"),
        ("nan,3", "not a goal"),
        ("1e999,3", "too large"),
        ("!!", "not a goal"),
        ("stale experience 3", "only objects are stale"),
        ("object 99999999999", "larger than any id"),
        ("car seen lots of times", "cannot read its filters"),
        ("car in session two", "cannot read its filters"),
    ],
)
def test_what_is_not_a_goal_is_one_error_naming_it(text, problem):
    with pytest.raises(GoalError, match=problem) as refused:
        parse_goal(text)
    assert "\n" not in str(refused.value)
    if text.strip():
        assert repr(text) in str(refused.value)


@settings(max_examples=50, deadline=None)
@given(st.text(max_size=40))
def test_any_text_is_a_goal_or_a_goal_error(text):
    try:
        goal = parse_goal(text)
    except GoalError:
        return
    assert parse_goal(goal.describe()) == goal


@given(
    st.floats(-1e6, 1e6, allow_nan=False),
    st.floats(-1e6, 1e6, allow_nan=False),
    st.none() | st.floats(-1e3, 1e3, allow_nan=False),
)
def test_a_point_reads_back_exactly(x, y, z):
    goal = PointGoal(x, y, z)
    assert parse_goal(goal.describe()) == goal
