"""The goal language: what a user or a program asks a route to reach, read into a typed goal.

A goal is one line of text, case and extra spaces ignored:

    experience 40                 an experience of the map, by id
    keyframe 7                    the experience made with a keyframe, by the keyframe's id
    12.5,-3   12.5, -3, 1.2       a point in the map's frame, metres (x, y and optionally z)
    x=12.5 y=-3   x=12.5 y=-3 z=1
    start                         where the latest session started (its first experience)
    start of session 2            where session 2 started
    object 12                     an object of the map, by id
    truck   nearest truck         the truck nearest by route (a class query: "nearest" is what a bare class means)
    the truck                     the only truck of the map: more than one is ambiguous, and refused
    car seen 3+ times             a car seen at least 3 times (also "seen at least 3 times")
    car in session 2              a car that session 2 saw (from experiences session 2 made)
    stale truck   stale object 4  stale objects too (an object not seen where it should have been; see staleness)

An object query is `[stale] [the | nearest | a | an | any] CLASS [seen N+ times] [in session S]`, the filters in
either order; CLASS is one of the map's labels (several words allowed, as "traffic light"). A stale object is no
goal unless the goal says `stale` (or the caller allows stale objects: `neoslam route --stale`). Every goal has a
canonical text (`describe()`), which parses back to the same goal.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from neoslam.errors import GoalError

__all__ = [
    "ExperienceGoal",
    "Goal",
    "KeyframeGoal",
    "ObjectGoal",
    "ObjectQuery",
    "PointGoal",
    "StartGoal",
    "parse_goal",
]

_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:e[-+]?\d+)?"  # finite decimals only: no nan, no inf
_ID = re.compile(r"^(experience|keyframe|object)\s+(\d+)$")
_POINT = re.compile(rf"^({_NUMBER})\s*,\s*({_NUMBER})(?:\s*,\s*({_NUMBER}))?$")
_NAMED_POINT = re.compile(rf"^x\s*=\s*({_NUMBER})[\s,]+y\s*=\s*({_NUMBER})(?:[\s,]+z\s*=\s*({_NUMBER}))?$")
_START = re.compile(r"^start(?:\s+of\s+session\s+(\d+))?$")
_SEEN = re.compile(r"\s+seen\s+(?:at\s+least\s+(\d+)|(\d+)\s*\+)\s+times?$")
_SESSION = re.compile(r"\s+in\s+session\s+(\d+)$")
_ARTICLES = {"the": True, "nearest": False, "a": False, "an": False, "any": False}  # word -> must be unique
_LABEL = re.compile(r"^[a-z][a-z0-9_-]*(?: [a-z0-9_-]+)*$")
_MAX_ID = 2**31 - 1  # the map file's ids are 32-bit


@dataclass(frozen=True)
class ExperienceGoal:
    """An experience of the map, by id."""

    id: int

    def describe(self) -> str:
        return f"experience {self.id}"


@dataclass(frozen=True)
class KeyframeGoal:
    """The experience made with a keyframe, by the keyframe's id."""

    id: int

    def describe(self) -> str:
        return f"keyframe {self.id}"


@dataclass(frozen=True)
class PointGoal:
    """A point in the map's frame, metres; z None: any height (distances are in the ground plane)."""

    x: float
    y: float
    z: float | None = None

    def describe(self) -> str:
        return ",".join(repr(float(v)) for v in (self.x, self.y) + (() if self.z is None else (self.z,)))


@dataclass(frozen=True)
class StartGoal:
    """Where a session started: its first experience; session None: the latest session that made experiences."""

    session: int | None = None

    def describe(self) -> str:
        return "start" if self.session is None else f"start of session {self.session}"


@dataclass(frozen=True)
class ObjectGoal:
    """An object of the map, by id; `stale`: also if it is stale."""

    id: int
    stale: bool = False

    def describe(self) -> str:
        return f"{'stale ' if self.stale else ''}object {self.id}"


@dataclass(frozen=True)
class ObjectQuery:
    """An object by its class: the one nearest by route among those that pass the filters, or with `unique` the
    only one (more is ambiguous)."""

    label: str
    unique: bool = False
    min_observations: int | None = None
    session: int | None = None
    stale: bool = False

    def describe(self) -> str:
        words = ["the" if self.unique else "nearest"] + (["stale"] if self.stale else []) + [self.label]
        if self.min_observations is not None:
            words.append(f"seen {self.min_observations}+ times")
        if self.session is not None:
            words.append(f"in session {self.session}")
        return " ".join(words)


Goal = ExperienceGoal | KeyframeGoal | PointGoal | StartGoal | ObjectGoal | ObjectQuery


def parse_goal(text: str) -> Goal:
    """The goal a line of the goal language names (see the module's grammar); GoalError naming it otherwise."""
    line = " ".join(str(text).lower().split())
    if not line:
        raise GoalError("empty goal: name a place or an object (e.g. 'start', 'experience 12', 'truck', '12.5,-3')")
    stale = line.startswith("stale ")
    body = line[len("stale ") :] if stale else line
    if found := _ID.match(body):
        kind, number = found.group(1), _number(found.group(2), text)
        if kind == "object":
            return ObjectGoal(number, stale)
        if stale:
            raise GoalError(f"goal {text!r}: only objects are stale; say {kind} {number}, or stale object N")
        return ExperienceGoal(number) if kind == "experience" else KeyframeGoal(number)
    if not stale and (found := _POINT.match(line) or _NAMED_POINT.match(line)):
        x, y, z = (None if value is None else float(value) for value in found.groups())
        assert x is not None and y is not None  # the patterns require both
        if not all(math.isfinite(v) for v in (x, y, 0.0 if z is None else z)):
            raise GoalError(f"goal {text!r}: a coordinate too large to be a place on a map")
        return PointGoal(x, y, z)
    if not stale and (found := _START.match(line)):
        return StartGoal(None if found.group(1) is None else _number(found.group(1), text))
    return _object_query(line, text)


def _object_query(line: str, text: str) -> ObjectQuery:
    """`[stale] [article] CLASS [seen N+ times] [in session S]`, the filters in either order."""
    body, min_observations, session = line, None, None
    while True:
        if min_observations is None and (found := _SEEN.search(body)):
            min_observations = _number(found.group(1) or found.group(2), text)
            body = body[: found.start()]
        elif session is None and (found := _SESSION.search(body)):
            session = _number(found.group(1), text)
            body = body[: found.start()]
        else:
            break
    words = body.split()
    stale, unique, article = False, False, None
    while words and (words[0] == "stale" and not stale or words[0] in _ARTICLES and article is None):
        word = words.pop(0)
        if word == "stale":
            stale = True
        else:
            article, unique = word, _ARTICLES[word]
    if "seen" in words or "session" in words:
        raise GoalError(
            f"goal {text!r}: cannot read its filters; say CLASS seen N+ times, CLASS seen at least N times, or "
            "CLASS in session S"
        )
    label = " ".join(words)
    if not _LABEL.match(label) or label in ("experience", "keyframe", "object", "start"):
        raise GoalError(
            f"goal {text!r}: not a goal; say experience N, keyframe N, object N, X,Y, start, start of session N, "
            "or an object class with its filters (e.g. 'nearest car seen 3+ times in session 2')"
        )
    return ObjectQuery(label, unique, min_observations, session, stale)


def _number(digits: str, text: str) -> int:
    value = int(digits)
    if value > _MAX_ID:
        raise GoalError(f"goal {text!r}: {value} is larger than any id of a map ({_MAX_ID})")
    return value
