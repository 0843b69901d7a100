"""Navigation on the map (beyond the paper): routes on the experience map to places and objects, and guidance
along them during a run.

`plan_route(map, goal)` plans on a stored `MapState` or a running `NeoSLAM`; goals are lines of a small language
(`neoslam.navigation.goals`: "experience 40", "12.5,-3", "start", "nearest truck", "the car in session 2", ...);
objects the robot should have seen again and did not are stale (`neoslam.navigation.staleness`); a `Guide` turns a
route and the robot's pose into the next waypoint's distance and bearing, the distance left and arrival, planning
again when the robot leaves the route. Modules: `view` (what is read of a map), `graph` (the navigation graph),
`goals` (the language), `resolution` (goals against a map), `staleness`, `route`, `guidance`.
"""

from neoslam.navigation.goals import (
    ExperienceGoal,
    Goal,
    KeyframeGoal,
    ObjectGoal,
    ObjectQuery,
    PointGoal,
    StartGoal,
    parse_goal,
)
from neoslam.navigation.graph import NavigationGraph
from neoslam.navigation.guidance import Guidance, GuidanceState, Guide
from neoslam.navigation.resolution import ResolvedGoal
from neoslam.navigation.route import Route, RoutePlanner, plan_route
from neoslam.navigation.staleness import MapObjects, ObjectStatus, map_objects, object_statuses
from neoslam.navigation.view import MapView, map_view, pose_in_map

__all__ = [
    "ExperienceGoal",
    "Goal",
    "Guidance",
    "GuidanceState",
    "Guide",
    "KeyframeGoal",
    "MapObjects",
    "MapView",
    "NavigationGraph",
    "ObjectGoal",
    "ObjectQuery",
    "ObjectStatus",
    "PointGoal",
    "ResolvedGoal",
    "Route",
    "RoutePlanner",
    "StartGoal",
    "map_objects",
    "map_view",
    "object_statuses",
    "parse_goal",
    "plan_route",
    "pose_in_map",
]
