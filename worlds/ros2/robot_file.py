"""The robot file of `sme world ros2 --robot FILE.toml`: which topics are sensors, what the action
sends, how the goal is recognised, the start poses and the control rate (docs/ros2.md).

Everything that can be checked without the robot is checked here (`load` raises a RobotFileError
naming the key and its valid values); what the robot offers is checked at start-up by the world."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from typing import Any

from sensorimotor.worlds.ros2.cdr import DISTROS

JOINT_STATE = "sensor_msgs/msg/JointState"
IMAGE = "sensor_msgs/msg/Image"
TWIST = "geometry_msgs/msg/Twist"
MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
COMMAND_TYPES = (JOINT_STATE, TWIST, MULTI_ARRAY)
SECTIONS = ("robot", "sensor", "action", "goal", "start")


class RobotFileError(ValueError):
    """A robot file that cannot be used; the message names the key and what is valid."""


@dataclass(frozen=True)
class SensorMap:
    """A topic served as sensor `name`: an Image (grey float32 [H, W] in [0, 1]) or the numbers at
    `field` (float32 vector; for a JointState, the `joints` named, in that order)."""

    name: str
    topic: str
    type: str = ""  # empty: whatever the robot publishes there
    field: str = ""
    joints: tuple[str, ...] = ()
    serve: bool = True  # False: read (for relative commands, start poses) but not sent to the agent


@dataclass(frozen=True)
class ActionMap:
    """What each action sends on `topic`: `discrete` rows (one per action index) or a box between
    `low` and `high`, each value going to the command's `fields` (Twist axes such as ``linear.x``),
    `joints` (JointState, as `field` ``position`` or ``velocity``) or to ``data`` in order.
    With `relative_to` (a sensor), a position command is the values added to that sensor's reading."""

    topic: str
    type: str
    discrete: tuple[tuple[float, ...], ...] = ()
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    names: tuple[str, ...] = ()
    field: str = "position"
    joints: tuple[str, ...] = ()
    fields: tuple[str, ...] = ()
    relative_to: str = ""

    @property
    def width(self) -> int:
        """Values one command carries."""
        return len(self.discrete[0]) if self.discrete else len(self.low)


@dataclass(frozen=True)
class GoalMap:
    """Where the goal comes from: a `reward` topic's number, or a `success` topic's flag (reward 1);
    the episode ends when the reward reaches `end_at` (success: when the flag is set)."""

    kind: str  # reward | success
    topic: str
    field: str = "data"
    end_at: float | None = None


@dataclass(frozen=True)
class StartMap:
    """Start states: joint poses sent as absolute position commands on the action's topic (the
    robot is driven there), reached when the `sensor` reads within `tolerance` of them."""

    poses: tuple[tuple[float, ...], ...]
    names: tuple[str, ...]
    sensor: str
    tolerance: float = 0.01
    timeout: float = 5.0


@dataclass(frozen=True)
class RobotFile:
    """A parsed robot file."""

    sensors: tuple[SensorMap, ...]
    action: ActionMap
    goal: GoalMap
    start: StartMap | None = None
    connect: str = "tcp/127.0.0.1:7447"
    domain: int = 0
    distro: str = "jazzy"
    rate: float = 50.0
    settle: float = 1.0
    discovery_timeout: float = 5.0
    node: str = "sme_world"
    namespace: str = "/"
    max_episode_steps: int = 200
    embedding_topic: str = "/sme/embedding"
    source: str = field(default="", compare=False)


def _get(table: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str, default: Any = ...) -> Any:
    if key not in table:
        if default is ...:
            raise RobotFileError(f"{where}: `{key}` is required")
        return default
    v = table[key]
    if kind is float and isinstance(v, int) and not isinstance(v, bool):
        v = float(v)
    if not isinstance(v, kind) or (kind is int and isinstance(v, bool)):
        name = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise RobotFileError(f"{where}: `{key}` must be {name}, not {v!r}")
    if isinstance(v, float) and not math.isfinite(v):
        raise RobotFileError(f"{where}: `{key}` must be finite")
    return v


def _only(table: dict[str, Any], keys: tuple[str, ...], where: str) -> None:
    bad = [k for k in table if k not in keys]
    if bad:
        raise RobotFileError(f"{where}: unknown key `{bad[0]}`; valid: {', '.join(keys)}")


def _numbers(v: Any, where: str) -> tuple[float, ...]:
    if not isinstance(v, list) or not v or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in v):
        raise RobotFileError(f"{where}: a non-empty list of numbers, not {v!r}")
    return tuple(float(x) for x in v)


def _strings(v: Any, where: str) -> tuple[str, ...]:
    if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
        raise RobotFileError(f"{where}: a list of names, not {v!r}")
    return tuple(v)


def _sensors(rows: Any) -> tuple[SensorMap, ...]:
    if not isinstance(rows, list) or not rows:
        raise RobotFileError("robot file: at least one [[sensor]] table is required")
    out = []
    for i, t in enumerate(rows):
        where = f"[[sensor]] #{i + 1}"
        _only(t, ("name", "topic", "type", "field", "joints", "serve"), where)
        s = SensorMap(
            name=_get(t, "name", str, where),
            topic=_get(t, "topic", str, where),
            type=_get(t, "type", str, where, ""),
            field=_get(t, "field", str, where, ""),
            joints=_strings(t.get("joints", []), f"{where} joints"),
            serve=_get(t, "serve", bool, where, True),
        )
        if s.type not in ("", IMAGE) and not s.field:
            raise RobotFileError(f"{where} ({s.name}): `field` is required for {s.type} (the numbers to read)")
        out.append(s)
    if not any(s.serve for s in out):
        raise RobotFileError("[[sensor]]: at least one sensor must be served to the agent (serve = true)")
    names = [s.name for s in out]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise RobotFileError(f"[[sensor]]: the name {dup!r} is used twice")
    return tuple(out)


def _action(t: Any) -> ActionMap:
    if not isinstance(t, dict):
        raise RobotFileError("robot file: an [action] table is required")
    where = "[action]"
    keys = ("topic", "type", "discrete", "box", "names", "field", "joints", "fields", "relative_to")
    _only(t, keys, where)
    kind = _get(t, "type", str, where)
    if kind not in COMMAND_TYPES:
        raise RobotFileError(f"{where}: command type {kind!r}; valid: {', '.join(COMMAND_TYPES)}")
    discrete: tuple[tuple[float, ...], ...] = ()
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    if "discrete" in t:
        rows = t["discrete"]
        if not isinstance(rows, list) or not rows:
            raise RobotFileError(f"{where}: `discrete` must list the values each action index sends")
        discrete = tuple(_numbers(r, f"{where} discrete[{i}]") for i, r in enumerate(rows))
        if len({len(r) for r in discrete}) != 1:
            raise RobotFileError(f"{where}: every `discrete` row must have as many values")
    elif "box" in t:
        box = t["box"]
        if not isinstance(box, dict):
            raise RobotFileError(f"{where}: `box` must be a table {{low = [...], high = [...]}}")
        low, high = _numbers(box.get("low"), f"{where} box.low"), _numbers(box.get("high"), f"{where} box.high")
        if len(low) != len(high) or any(lo >= hi for lo, hi in zip(low, high, strict=True)):
            raise RobotFileError(f"{where}: box.low and box.high must be as long, each low below its high")
    else:
        raise RobotFileError(f"{where}: give `discrete` (values per action index) or `box` (low, high)")
    a = ActionMap(
        topic=_get(t, "topic", str, where),
        type=kind,
        discrete=discrete,
        low=low,
        high=high,
        names=_strings(t.get("names", []), f"{where} names"),
        field=_get(t, "field", str, where, "position"),
        joints=_strings(t.get("joints", []), f"{where} joints"),
        fields=_strings(t.get("fields", []), f"{where} fields"),
        relative_to=_get(t, "relative_to", str, where, ""),
    )
    if a.names and len(a.names) != (len(discrete) if discrete else len(low)):
        raise RobotFileError(f"{where}: `names` must name every action ({len(discrete) or len(low)})")
    if kind == JOINT_STATE:
        if a.field not in ("position", "velocity"):
            raise RobotFileError(f"{where}: JointState commands send `field` position or velocity, not {a.field!r}")
        if len(a.joints) != a.width:
            raise RobotFileError(f"{where}: `joints` must name one joint per value ({a.width})")
    if kind == TWIST:
        axes = [f"{p}.{x}" for p in ("linear", "angular") for x in "xyz"]
        bad = [f for f in a.fields if f not in axes]
        if bad or len(a.fields) != a.width:
            raise RobotFileError(
                f"{where}: Twist `fields` must name one axis per value ({a.width}); valid: {', '.join(axes)}"
            )
    if a.relative_to and (kind == TWIST or a.field != "position"):
        raise RobotFileError(
            f"{where}: `relative_to` is for position commands (JointState position, Float64MultiArray)"
        )
    return a


def _goal(t: Any) -> GoalMap:
    if not isinstance(t, dict):
        raise RobotFileError("robot file: a [goal] table is required (a reward or a success topic)")
    where = "[goal]"
    _only(t, ("reward", "success", "end_at"), where)
    kinds = [k for k in ("reward", "success") if k in t]
    if len(kinds) != 1:
        raise RobotFileError(f"{where}: give exactly one of `reward` or `success` ({{topic = ..., field = ...}})")
    kind = kinds[0]
    src = t[kind]
    if not isinstance(src, dict):
        raise RobotFileError(f"{where}: `{kind}` must be a table {{topic = ..., field = ...}}")
    _only(src, ("topic", "field"), f"{where} {kind}")
    end_at = _get(t, "end_at", float, where, None)
    return GoalMap(
        kind, _get(src, "topic", str, f"{where} {kind}"), _get(src, "field", str, f"{where} {kind}", "data"), end_at
    )


def _start(t: Any, action: ActionMap, sensors: tuple[SensorMap, ...]) -> StartMap | None:
    if t is None:
        return None
    where = "[start]"
    _only(t, ("poses", "grid", "sensor", "tolerance", "timeout", "service"), where)
    if "service" in t:
        raise RobotFileError(
            f"{where}: a reset service is not supported yet; list `poses` or `grid`, or leave [start] out"
        )
    if action.type == TWIST or action.field != "position":
        raise RobotFileError(
            f"{where}: start poses are reached by position commands; this action sends {action.type} {action.field}"
        )
    names: list[str] = []
    poses: list[tuple[float, ...]] = []
    if "poses" in t:
        tab = t["poses"]
        if not isinstance(tab, dict) or not tab:
            raise RobotFileError(f"{where}: `poses` must be a table of name = [one value per joint]")
        for n, v in tab.items():
            names.append(n)
            poses.append(_numbers(v, f"{where} poses.{n}"))
    elif "grid" in t:
        axes = t["grid"]
        if not isinstance(axes, list) or not axes:
            raise RobotFileError(f"{where}: `grid` must list each joint's values")
        vals = [_numbers(a, f"{where} grid[{i}]") for i, a in enumerate(axes)]
        import itertools

        for combo in itertools.product(*vals):
            poses.append(tuple(combo))
            names.append("_".join(f"{x:g}" for x in combo))
    else:
        raise RobotFileError(f"{where}: give `poses` or `grid` (or leave [start] out: learned, not embedded)")
    if any(len(p) != action.width for p in poses):
        raise RobotFileError(f"{where}: every pose needs one value per commanded joint ({action.width})")
    sensor = _get(t, "sensor", str, where, action.relative_to)
    if sensor not in [s.name for s in sensors]:
        raise RobotFileError(
            f"{where}: `sensor` {sensor!r} (read to know a pose is reached); valid: {', '.join(s.name for s in sensors)}"
        )
    tol = _get(t, "tolerance", float, where, 0.01)
    timeout = _get(t, "timeout", float, where, 5.0)
    if tol <= 0 or timeout <= 0:
        raise RobotFileError(f"{where}: `tolerance` and `timeout` must be > 0")
    return StartMap(tuple(poses), tuple(names), sensor, tol, timeout)


def parse(doc: dict[str, Any], source: str = "") -> RobotFile:
    """A RobotFile from a parsed TOML document."""
    _only(doc, SECTIONS, "robot file")
    r = doc.get("robot", {})
    where = "[robot]"
    keys = ("connect", "domain", "distro", "rate", "settle", "discovery_timeout", "node", "namespace")
    _only(r, (*keys, "max_episode_steps", "embedding_topic"), where)
    sensors = _sensors(doc.get("sensor"))
    action = _action(doc.get("action"))
    if action.relative_to and action.relative_to not in [s.name for s in sensors]:
        raise RobotFileError(
            f"[action]: `relative_to` {action.relative_to!r}; valid sensors: {', '.join(s.name for s in sensors)}"
        )
    distro = _get(r, "distro", str, where, "jazzy")
    if distro not in DISTROS:
        raise RobotFileError(f"{where}: distro {distro!r}; valid: {', '.join(DISTROS)}")
    out = RobotFile(
        sensors=sensors,
        action=action,
        goal=_goal(doc.get("goal")),
        start=_start(doc.get("start"), action, sensors),
        connect=_get(r, "connect", str, where, "tcp/127.0.0.1:7447"),
        domain=_get(r, "domain", int, where, 0),
        distro=distro,
        rate=_get(r, "rate", float, where, 50.0),
        settle=_get(r, "settle", float, where, 1.0),
        discovery_timeout=_get(r, "discovery_timeout", float, where, 5.0),
        node=_get(r, "node", str, where, "sme_world"),
        namespace=_get(r, "namespace", str, where, "/"),
        max_episode_steps=_get(r, "max_episode_steps", int, where, 200),
        embedding_topic=_get(r, "embedding_topic", str, where, "/sme/embedding"),
        source=source,
    )
    if not 0 < out.rate <= 1000 or out.settle < 0 or out.discovery_timeout <= 0 or out.max_episode_steps < 1:
        raise RobotFileError(f"{where}: rate in (0, 1000], settle >= 0, discovery_timeout > 0, max_episode_steps >= 1")
    if not 0 <= out.domain <= 232:
        raise RobotFileError(f"{where}: domain {out.domain} outside ROS 2's 0..232")
    return out


def load(path: str) -> RobotFile:
    """Read and check a robot file; a RobotFileError says what is wrong (TOML syntax included)."""
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as e:
        raise RobotFileError(f"robot file {path}: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise RobotFileError(f"robot file {path}: not TOML ({e})") from None
    try:
        return parse(doc, path)
    except RobotFileError as e:
        raise RobotFileError(f"{path}: {e}") from None
