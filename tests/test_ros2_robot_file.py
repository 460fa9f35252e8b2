"""The robot file of `sme world ros2`: the two examples of docs/ros2.md and the stand-in's parse,
and a file that cannot be used is refused naming the key and what is valid (no robot needed)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from sensorimotor.worlds.ros2.robot_file import RobotFileError, load, parse

ROOT = Path(__file__).resolve().parents[1]
STANDIN = ROOT / "tests" / "data" / "standin_arm_ros2.toml"


def doc_files() -> list[dict]:
    text = (ROOT / "docs" / "ros2.md").read_text()
    return [tomllib.loads(b) for b in re.findall(r"```toml\n(.*?)```", text, re.S)]


def test_the_docs_examples_and_the_stand_in_file_parse():
    arm, base = (parse(d) for d in doc_files())
    assert arm == load(str(STANDIN))  # the page shows the file the tests use
    assert len(arm.start.poses) == 49 and arm.start.poses[1] == (-0.2, 0.0) and arm.action.relative_to == "joints"
    assert base.start is None and base.distro == "humble" and base.action.fields == ("linear.x", "angular.z")
    assert base.goal.kind == "success" and base.action.discrete[1] == (0.0, 0.5)


BASE = tomllib.loads(STANDIN.read_text())


def edited(path: str, value: object) -> dict:
    """The stand-in file with `path` (dotted; `sensor.0.field`) set to `value` (None: removed)."""
    import copy

    doc = copy.deepcopy(BASE)
    *head, last = path.split(".")
    node = doc
    for k in head:
        node = node[int(k)] if k.isdigit() else node[k]
    if value is None:
        del node[last]
    else:
        node[last] = value
    return doc


@pytest.mark.parametrize(
    "path, value, words",
    [
        ("robot.distro", "iron", "distro 'iron'; valid: humble, jazzy, kilted, rolling"),
        ("robot.rate", "fast", "`rate` must be float"),
        ("robot.colour", 1, "unknown key `colour`; valid: connect, domain"),
        ("action.type", "std_msgs/msg/String", "command type 'std_msgs/msg/String'; valid: sensor_msgs/msg/JointState"),
        ("action.discrete", [[0.2], [0.1, 0.2]], "every `discrete` row must have as many values"),
        ("action.joints", ["a"], "`joints` must name one joint per value (2)"),
        ("action.relative_to", "elbow", "`relative_to` 'elbow'; valid sensors: camera, joints"),
        ("action.field", "effort", "JointState commands send `field` position or velocity"),
        ("goal.reward", None, "give exactly one of `reward` or `success`"),
        ("start.grid", [[0.0, 0.2]], "every pose needs one value per commanded joint (2)"),
        ("start.service", "/reset", "a reset service is not supported yet"),
        ("sensor.1.field", None, "`field` is required for sensor_msgs/msg/JointState"),
        ("sensor.0.serve", False, None),  # both sensors unserved
    ],
)
def test_a_file_that_cannot_be_used_names_the_key_and_the_choices(path, value, words):
    doc = edited(path, value)
    if words is None:
        doc["sensor"][1]["serve"] = False
        words = "at least one sensor must be served"
    with pytest.raises(RobotFileError) as e:
        parse(doc)
    assert words in str(e.value)


def test_a_twist_action_names_its_axes(tmp_path):
    doc = edited("action.type", "geometry_msgs/msg/Twist")
    del doc["action"]["relative_to"], doc["action"]["field"], doc["start"]
    doc["action"]["fields"] = ["linear.x", "angular.w"]
    with pytest.raises(RobotFileError, match="valid: linear.x, linear.y, linear.z, angular.x"):
        parse(doc)
    bad = tmp_path / "bad.toml"
    bad.write_text("[robot\n")
    with pytest.raises(RobotFileError, match="not TOML"):
        load(str(bad))
    with pytest.raises(RobotFileError, match="No such file"):
        load(str(tmp_path / "missing.toml"))
