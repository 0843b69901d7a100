"""Navigation on the map: routes, goals, stale objects and guidance along a route."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from neoslam.config.base import Section

__all__ = ["NavigationConfig"]


class NavigationConfig(Section):
    """Routes on the experience map to places and objects, and guidance along them (`neoslam route`,
    neoslam.navigation; beyond the paper). A route follows the map's links, both ways; distances are in the map's
    ground plane unless said otherwise."""

    cost: Literal["length", "time"] = Field(
        "length",
        description="what a route minimises: length, metres along the links; time, the expected travel time (each "
        "link's length over the speed its experiences were made at, or expected_speed where they recorded none)",
    )
    expected_speed: float = Field(
        8.0,
        gt=0,
        le=100,
        description="speed assumed on a link whose experiences recorded none (slower than min_known_speed), m/s: "
        "the route's expected time, and its cost with cost: time (8 m/s, about 29 km/h in town)",
    )
    min_known_speed: float = Field(
        0.5,
        ge=0,
        le=100,
        description="an experience made slower than this (standing, starting) gives its links no speed, m/s",
    )
    goal_radius: float = Field(
        10.0,
        gt=0,
        le=1000,
        description="a goal that is an object or a point is reached from the experiences within this distance of "
        "it, m: the route ends at the one whose route plus straight distance to the goal is shortest (none within: "
        "at the nearest experience); guidance to a point this near goes on to the point",
    )
    max_goal_distance: float = Field(
        50.0,
        gt=0,
        le=100_000,
        description="a point goal farther than this from every experience is refused, m: the map does not go there",
    )
    arrival_radius: float = Field(
        5.0,
        gt=0,
        le=1000,
        description="guidance: the robot has arrived once it has reached the route's end (the goal's position) within "
        "this distance of it, m: how far beside the end it may be; within it, a robot with the end abeam or behind "
        "it has reached the end (it comes no nearer by driving on)",
    )
    end_reached: float = Field(
        0.5,
        gt=0,
        le=100,
        description="guidance: a robot projected onto the route this close to its end, along it, has reached the "
        "end, m: a robot that stops when told it arrived stops there, not on the rim of arrival_radius",
    )
    look_ahead: float = Field(
        8.0,
        ge=0,
        le=1000,
        description="guidance: the next waypoint is the first route experience at least this far ahead of the "
        "robot along the route, m (experiences are about 5 m apart: the waypoint is one or two ahead)",
    )
    waypoint_reached: float = Field(
        3.0,
        ge=0,
        le=1000,
        description="guidance: a robot this close to its next waypoint has reached it, m: it is followed on from "
        "there (a route that turns back on itself passes its own earlier part, nearer to the robot than the part "
        "it is on; 0: only by the projection)",
    )
    off_route_distance: float = Field(
        12.0,
        gt=0,
        le=1000,
        description="guidance: farther than this from the route (in the ground plane), the robot has left it and "
        "the route is planned again from where it is, m (above a corrected map's error, below a block's width)",
    )
    jump_distance: float = Field(
        10.0,
        gt=0,
        le=1000,
        description="guidance: a pose that moved farther than this since the previous frame was relocalised or "
        "corrected, m: the route is planned again from where the robot now is (a car at 70 m/s and 10 Hz moves 7 m)",
    )
    view_range: float = Field(
        20.0,
        gt=0,
        le=1000,
        description="stale objects: an object counts as in view of an experience up to this distance, m (well "
        "inside camera.max_range, where the detector finds nearly every object it faces)",
    )
    view_min_range: float = Field(
        5.0,
        ge=0,
        le=1000,
        description="stale objects: and from this distance on, m (a near object is cut by the image's border, or "
        "passes out of view between two frames)",
    )
    field_of_view_deg: float = Field(
        60.0,
        gt=0,
        le=360,
        description="stale objects: the part of the camera's horizontal field of view, degrees, centred on the "
        "robot's x axis, in which an object should be seen (KITTI's left camera sees 82; near its edges boxes are "
        "cut by the image's border, and on the simulated block and town drives, with every object in place, the "
        "experiences turning a corner with an object there missed it)",
    )
    stale_after_misses: int = Field(
        3,
        ge=1,
        le=10_000,
        description="stale objects: an object is stale once this many experiences made after its last sighting "
        "had it in view and did not see it (a parked car that left); a stale object is no goal unless asked for",
    )

    confirm_radius: float = Field(
        3.0,
        gt=0,
        le=100,
        description="guidance to an object: an observation of the goal's class this close to the goal object (in "
        "the map, at the robot's pose) is a sighting of it, m; arriving at an object this session never sighted (in "
        "a frame, in the map's record of it when the route is planned, or in the recall_frames before it "
        "relocalised) is looked at for look_time, then reported missing, not arrived (a parked car that left)",
    )
    sighting_margin: float = Field(
        1.0,
        ge=0,
        le=100,
        description="guidance to an object: an observation is a sighting of the goal only when it lies nearer to the "
        "goal than to any other object of its class in the map by this many stds of its place: its depth's (the "
        "object map's: object_map.depth_sigma_at_1m times depth squared, or the front end's own when larger) and "
        "the goal's own in the map (one over the root of its observations' summed weights) together: a far view of "
        "a car beside a goal that left, metres off along its ray, could be either and sights neither; so could a "
        "near one beside a goal the map placed from a few far views",
    )
    sightings: int = Field(
        2,
        ge=1,
        le=100,
        description="guidance to an object: frames with a sighting that see the goal object (one far observation "
        "of a neighbour, its stereo depth metres off at 50 m, can land on it)",
    )
    recall_frames: int = Field(
        100,
        ge=0,
        le=100_000,
        description="guidance to an object: the frames before the session relocalised whose observations count as "
        "sightings once it has (placed by the odometry since: 100 frames, 10 s at 10 Hz); a robot that passed the "
        "goal just before it relocalised has seen it",
    )
    look_time: float = Field(
        4.0,
        ge=0,
        le=3600,
        description="guidance to an object: a robot that reaches an object goal it has not sighted is asked to look "
        "at it (state looking, the bearing to the object) for up to this long before it is reported missing, s "
        "(a U-turn in place takes about 2 s; 0: missing at once)",
    )
    rivals_within: float = Field(
        3.0,
        gt=0,
        le=100,
        description="guidance to an object: the map's other objects of the goal's class within this many "
        "confirm_radius of it compete for an observation: one nearer to them than to the goal is theirs",
    )
    copy_gap: int = Field(
        2,
        ge=0,
        le=1_000_000,
        description="guidance to an object: a rival (see rivals_within) that no experience within this many "
        "experience ids of one that saw the goal ever saw is taken for a copy of the goal (one car placed twice by "
        "two passes that disagreed by more than the object map's association radius), not a rival: an observation "
        "between the two is the goal's. Two cars side by side are seen on one pass; 0: no copies",
    )

    @model_validator(mode="after")
    def _view_band(self) -> NavigationConfig:
        if self.view_min_range >= self.view_range:
            raise ValueError(f"view_min_range ({self.view_min_range}) must be less than view_range ({self.view_range})")
        return self
