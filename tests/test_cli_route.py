"""`neoslam route`: a route on a map file, through the CLI. On a hand-built map (the ladder of streets): the files,
their bytes the same each time, the map left as it was, and every refusal one line with exit code 2 naming the goal.
End to end: a map made by a simulated drive with `neoslam run --map`, then routes to an object class and to the
start."""

from __future__ import annotations

import csv
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from tests.navigation.streets import ladder

from neoslam.config import NeoSLAMConfig
from neoslam.store.map_file import MapFile


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture(scope="module")
def ladder_map(tmp_path_factory) -> Path:
    """The ladder of streets as a map file, with a second session far away, never linked to the first."""
    streets = ladder()
    streets.builder.keyframes = {}  # a map file holds keyframes whole; these are ids only
    streets.builder.drive([(1000, 0), (1100, 0)], session=2)
    path = tmp_path_factory.mktemp("ladder") / "map.db"
    with MapFile.create(path, NeoSLAMConfig()) as map_file:
        map_file.commit(streets.state)
    return path


@pytest.mark.slow  # matplotlib draws the map: seconds
def test_a_route_to_a_class_is_written_as_csv_json_and_png(cli, ladder_map, tmp_path):
    before = _digest(ladder_map)
    result = cli.ok("route", ladder_map, "--to", "truck", "--from", "experience 60", "--out", tmp_path / "r")
    assert _digest(ladder_map) == before and sorted(p.name for p in ladder_map.parent.iterdir()) == ["map.db"]
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["route.csv", "route.json", "route.png"]
    for name in ("goal", "length [m]", "waypoints", "planning [ms]", "truck 1"):
        assert name in result.stdout
    rows = _rows(tmp_path / "r" / "route.csv")
    assert list(rows[0]) == ["waypoint", "experience", "x", "y", "z", "yaw", "distance_m"]
    assert rows[0]["experience"] == "60" and float(rows[0]["distance_m"]) == 0.0
    features = json.loads((tmp_path / "r" / "route.json").read_text())
    assert features["type"] == "FeatureCollection" and features["properties"]["frame"] == "map"
    assert "not WGS84" in features["properties"]["note"]
    line, start, goal = features["features"]
    assert line["geometry"]["type"] == "LineString" and len(line["geometry"]["coordinates"]) == len(rows)
    assert line["properties"]["length_m"] == pytest.approx(float(rows[-1]["distance_m"]))
    assert start["properties"] == {"role": "start", "experience": 60}
    assert goal["geometry"]["coordinates"] == [40.0, 55.0, 0.5] and goal["properties"]["object"]["label"] == "truck"
    assert goal["properties"]["ids"] == [1] and goal["properties"]["object"]["stale"] is False
    assert [float(rows[-1][c]) for c in ("x", "y")] == goal["properties"]["route_end"][:2]
    assert (tmp_path / "r" / "route.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # matplotlib draws the map: seconds
def test_the_same_map_and_goal_give_the_same_bytes(cli, ladder_map, tmp_path):
    for name in ("a", "b"):
        cli.ok("route", ladder_map, "--to", "start of session 1", "--from", "50,52", "--out", tmp_path / name)
    for file in ("route.csv", "route.json", "route.png"):
        assert _digest(tmp_path / "a" / file) == _digest(tmp_path / "b" / file)


@pytest.mark.parametrize(
    ("arguments", "parts"),
    [
        (["--to", "plane"], ["map.db", "goal 'nearest plane'", "no plane in the map", "car, person, truck"]),
        (["--to", "the truck"], ["goal 'the truck'", "ambiguous", "objects 0, 1"]),
        (["--to", "experience 5000"], ["goal 'experience 5000'", "no such experience"]),
        (["--to", "experience 0", "--from", "experience 120"], ["goal 'experience 0'", "no route"]),
        (["--to", "900,900"], ["goal '900.0,900.0'", "the map does not go there"]),
        (["--to", "car seen lots of times"], ["goal 'car seen lots of times'", "cannot read its filters"]),
        (["--to", ""], ["empty goal"]),
        (["--to", "truck", "--from", "truck"], ["start 'nearest truck'", "2 objects match"]),
    ],
)
def test_a_goal_that_cannot_be_reached_is_one_line(cli, ladder_map, tmp_path, arguments, parts):
    result = cli.invoke("route", ladder_map, *arguments, "--out", tmp_path / "r")
    cli.one_line_error(result, *parts)
    assert not (tmp_path / "r").exists()


@pytest.mark.slow  # matplotlib draws the map: seconds
def test_a_stale_goal_needs_stale(cli, tmp_path):
    streets = ladder()
    streets.builder.keyframes = {}
    streets.builder.drive([(130, -1), (175, -1)], session=2, after=streets.at(125, 0))  # past truck 0, unseen
    path = tmp_path / "map.db"
    with MapFile.create(path, NeoSLAMConfig()) as map_file:
        map_file.commit(streets.state)
    config = tmp_path / "navigation.yaml"
    config.write_text("navigation:\n  stale_after_misses: 2\n  field_of_view_deg: 80\n  view_min_range: 3\n")
    result = cli.invoke("route", path, "--to", "object 0", "--config", config, "--out", tmp_path / "r")
    cli.one_line_error(result, "goal 'object 0'", "is stale: last seen session 1", "--stale")
    result = cli.ok("route", path, "--to", "object 0", "--stale", "--config", config, "--out", tmp_path / "r")
    assert "stale" in result.stdout
    route = json.loads((tmp_path / "r" / "route.json").read_text())
    assert route["features"][2]["properties"]["object"]["stale"] is True


def test_an_empty_map_a_missing_map_and_an_output_over_the_map_are_refused(cli, tmp_path):
    MapFile.create(tmp_path / "empty.db", NeoSLAMConfig()).close()
    result = cli.invoke("route", tmp_path / "empty.db", "--to", "start", "--out", tmp_path / "r")
    cli.one_line_error(result, "empty.db", "empty map")
    result = cli.invoke("route", tmp_path / "none.db", "--to", "start", "--out", tmp_path / "r")
    cli.one_line_error(result, "none.db", "map not found")
    result = cli.invoke("route", tmp_path / "empty.db", "--to", "start", "--out", tmp_path / "empty.db")
    cli.one_line_error(result, "empty.db")
    assert not (tmp_path / "r").exists()


def test_a_map_made_with_other_settings_is_refused(cli, ladder_map, tmp_path):
    config = tmp_path / "other.yaml"
    config.write_text("keyframes:\n  spacing: 7.5\n")
    result = cli.invoke("route", ladder_map, "--to", "start", "--config", config, "--out", tmp_path / "r")
    cli.one_line_error(result, "map.db", "keyframes.spacing")


# End to end: a map from a simulated drive


@pytest.fixture(scope="module")
def drive_map(cli, tmp_path_factory) -> tuple[Path, Path, Path]:
    """The block route simulated and run with --map: the map, the dataset folder and the results folder."""
    root = tmp_path_factory.mktemp("drive")
    cli.ok("simulate", "--route", "block", "--noise", "vo", "--seed", "1", "--out", root / "street", "--quiet")
    cli.ok("run", root / "street", "--map", root / "map.db", "--out", root / "results", "--quiet")
    return root / "map.db", root / "street", root / "results"


@pytest.mark.slow
def test_a_route_to_an_object_class_on_a_map_from_a_drive(cli, drive_map, tmp_path):
    map_path, street, results = drive_map
    before = _digest(map_path)
    cli.ok("route", map_path, "--to", "nearest car", "--out", tmp_path / "car")
    assert _digest(map_path) == before
    goal = json.loads((tmp_path / "car" / "route.json").read_text())["features"][2]
    properties = goal["properties"]
    assert properties["kind"] == "object" and properties["object"]["label"] == "car"
    # the goal is the mapped car, where objects.csv has it; the route ends within a few metres of it
    mapped = {int(row["id"]): row for row in _rows(results / "objects.csv")}
    car = mapped[properties["ids"][0]]
    np.testing.assert_allclose(goal["geometry"]["coordinates"], [float(car[c]) for c in "xyz"], atol=1e-3)
    assert properties["offset_m"] <= NeoSLAMConfig().navigation.goal_radius
    # and a car of the simulated world stands there (the drive's map is in the first pose's frame, as its truth)
    truth = _rows(street / "truth" / "objects.csv")
    cars = np.array([[float(row["x"]), float(row["y"])] for row in truth if row["label"] == "car"])
    assert np.min(np.linalg.norm(cars - goal["geometry"]["coordinates"][:2], axis=1)) < 3.0


@pytest.mark.slow
def test_a_route_back_to_the_start_on_a_map_from_a_drive(cli, drive_map, tmp_path):
    map_path, _, results = drive_map
    result = cli.ok("route", map_path, "--to", "start", "--out", tmp_path / "start")
    assert "start of session 1 (experience 0)" in result.stdout
    rows = _rows(tmp_path / "start" / "route.csv")
    assert rows[-1]["experience"] == "0" and float(rows[-1]["distance_m"]) > 0
    first = np.loadtxt(results / "trajectory_tum.txt")[0, 1:3]
    assert np.linalg.norm([float(rows[-1]["x"]) - first[0], float(rows[-1]["y"]) - first[1]]) < 3.0
