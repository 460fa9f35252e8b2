"""A robot arm from any URDF, seen by a fixed camera, rendered headless with PyBullet.

The robot is loaded with a fixed base (`urdf`: a path inside `pybullet_data`, such as
``kuka_iiwa/model.urdf`` or ``franka_panda/panda.urdf``, or a file of the user's own). The joints
named by `joints` move (by default the `n_joints` that move the hand most at the rest pose); every
other joint is held at its rest angle (0, or the nearest limit). The body is moved kinematically
(joint angles are set, nothing is simulated), so a world step is one render at most.

Actions: ``discrete`` gives two per moving joint (+step, -step, in joint order); ``box`` gives one
increment in [-1, 1] x step per moving joint. A move that would leave the start lattice's range is
not made (the arm stays), as the object-pose box stays at its range.

Observation: the camera image, grey, `image` x `image` px, float32 in [0, 1]; with
`proprioception` (by default for 5 or more moving joints) also ``joints``, the moving joints'
angles (rad). The camera is placed once, from
the hand's positions over the lattice: it looks at their centre along the direction in which they
spread least, from far enough to see them all. A small green marker rides on the hand.

Start states: every pose of the lattice of `lattice` angles per moving joint, `step` apart, centred
on the rest pose (moved inside the joint's limits where needed); for 5 or more moving joints (or
`starts` > 0) `starts` poses of that lattice drawn at random (128 by default, seeded by the world's
seed): a 7-joint lattice has 823,543 poses. Truth: the moving joints' angles of each start
(``positions``) and the hand's 3-D position there (``hand``).

Perceptual goal: of the poses the body can reach, the one whose image shows the marker nearest the
image centre, found from rendered colour images alone (the marker is the only green); with sampled
starts, the start pose that shows it so. It is found again after every body change that alters what
is seen or reached. Reaching it (every moving joint within `goal_steps` steps and a half of it: 0
up to 4 moving joints, 1 beyond) gives reward 1 and ends the episode.

Body changes (`sme perturb`): ``morph`` scales a link's length (the URDF rewritten, the body
reloaded in place, the pose kept), ``lesion`` locks a joint where it is (starts then share its
angle), ``reverse`` flips a joint's command sign, ``gain`` scales its step, ``heal`` undoes all.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pybullet as p
import pybullet_data

from sensorimotor.protocol.messages import ActionSpace, Control, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, option, parse
from sensorimotor.worlds.base import HealParams, PerturbationError, StepResult, World
from sensorimotor.worlds.bullet import direct_client, disconnect

#: marker colours, tried in order: the first that no pixel of the robot itself shows is used
MARKER_COLOURS = ((0.0, 1.0, 0.0), (1.0, 0.0, 1.0), (0.0, 1.0, 1.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 1.0, 0.0))
_CACHE = 4096  # rendered observations kept (lattice poses repeat; off-lattice ones need a bound)


@dataclass(frozen=True)
class ArmWorldParams:
    """Parameters of the arm world."""

    urdf: str = option("kuka_iiwa/model.urdf", "the robot: a path inside pybullet_data or a URDF file of your own")
    joints: tuple[str, ...] = option((), "names of the moving joints (empty: the n_joints that move the hand most)")
    n_joints: int = option(2, "moving joints when `joints` is empty", min=1, max=7)
    hand: str = option("", "the hand link the marker rides on (empty: the end of the chain)")
    lattice: int = option(7, "start angles per moving joint (the start states: lattice^joints poses)", min=2, max=15)
    starts: int = option(
        0,
        "start poses drawn from the lattice (seeded by the world's seed); 0: the whole lattice up to 4 moving "
        "joints, 128 drawn beyond",
        min=0,
        max=4096,
    )
    goal_steps: int | None = option(
        None,
        "the goal is reached with every moving joint within this many steps (and a half) of the goal pose; "
        "none: 0 up to 4 moving joints, 1 beyond (a single pose of a 7-joint lattice is too rare to be found)",
        min=0,
        max=3,
    )
    bend: float = option(
        0.4, "the moving joints' angle at the lattice's centre, rad (nearest limit if outside)", min=-3.2, max=3.2
    )
    step: float = option(0.2, "joint increment of one action, rad (also the lattice spacing)", min=0.01, max=1.0)
    image: int = option(48, "camera image side, px (grey)", min=16, max=128)
    goal_image: int = option(96, "image side, px, the perceptual goal is found on", min=32, max=256)
    fov: float = option(50.0, "camera field of view, degrees", min=10.0, max=120.0)
    marker: float = option(0.04, "marker radius, m", min=0.005, max=0.5)
    proprioception: bool | None = option(
        None, "also serve the moving joints' angles as sensor `joints` (none: for 5 or more moving joints)"
    )
    actions: str = option(
        "discrete", "discrete (+-step per joint) or box (an increment per joint)", choices=("discrete", "box")
    )
    max_episode_steps: int = option(0, "actions after which an episode ends (0: 4 x the lattice's diameter)", min=0)


@dataclass(frozen=True)
class MorphParams:
    """Scale a link's length (its child joints' offsets and its shapes along them) by `scale`;
    the URDF is rewritten and the body reloaded in place, the pose kept (morphs multiply)."""

    link: str = option("", "the link to scale (empty: the link after the first moving joint)")
    scale: float = option(1.3, "length factor", min=0.5, max=2.0)


@dataclass(frozen=True)
class JointParams:
    """Lock a moving joint (a second lesion of it frees it); every start then shares its angle."""

    joint: str = option("", "the moving joint (empty: the first)")
    at: float | None = option(
        None, "lock it at this angle, rad, within the lattice's range (none: where it is)", min=-6.3, max=6.3
    )


@dataclass(frozen=True)
class ReverseParams:
    """Flip a moving joint's command sign (a second reverse restores it)."""

    joint: str = option("", "the moving joint (empty: the first)")


@dataclass(frozen=True)
class GainParams:
    """Scale a moving joint's step (replaces an earlier gain of it)."""

    joint: str = option("", "the moving joint (empty: the first)")
    gain: float = option(1.5, "step factor", min=0.25, max=4.0)


def colour_mask(rgb: np.ndarray, colour: tuple[float, float, float], margin: float = 0.35) -> np.ndarray:
    """Pixels of `rgb` ([H, W, 3] in [0, 1]) of the pure colour `colour`, whatever their shading:
    each channel that is on in `colour` exceeds every channel that is off by `margin`."""
    on = np.array(colour) > 0.5
    return rgb[..., on].min(axis=-1) - rgb[..., ~on].max(axis=-1) > margin


def resolve_urdf(path: str) -> str:
    """`path` as a file: itself if it exists, else inside `pybullet_data`; a ParamError otherwise."""
    for cand in (os.path.expanduser(path), os.path.join(pybullet_data.getDataPath(), path)):
        if os.path.isfile(cand):
            return os.path.abspath(cand)
    raise ParamError(f"arm: urdf {path!r} is neither a file nor in pybullet_data ({pybullet_data.getDataPath()})")


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    r, pch, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(pch), math.sin(pch), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _vec(text: str | None, default: float = 0.0) -> np.ndarray:
    return np.array([float(v) for v in text.split()]) if text else np.full(3, default)


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def scalable_links(root: ET.Element) -> list[str]:
    """Links whose length `morph` can scale: those with a child joint at a non-zero offset."""
    out = []
    for j in root.iter("joint"):
        o = j.find("origin")
        parent = j.find("parent")
        if parent is not None and o is not None and np.linalg.norm(_vec(o.get("xyz"))) > 1e-9:
            name = parent.get("link", "")
            if name not in out:
                out.append(name)
    return out


def morph_urdf(text: str, base_dir: str, scales: dict[str, float]) -> str:
    """The URDF `text` with each link of `scales` lengthened by its factor: its child joints'
    origins scaled, and its visual and collision shapes stretched along the direction of its first
    child joint; relative mesh paths (also ``package://``) made absolute against `base_dir`."""
    root = ET.fromstring(text)
    for mesh in root.iter("mesh"):
        f = mesh.get("filename", "")
        rel = f[len("package://") :] if f.startswith("package://") else f
        if not os.path.isabs(rel) and "://" not in rel:
            mesh.set("filename", os.path.join(base_dir, rel))
    links = {lk.get("name"): lk for lk in root.iter("link")}
    for name, s in scales.items():
        offsets = []
        for j in root.iter("joint"):
            parent = j.find("parent")
            o = j.find("origin")
            if parent is None or parent.get("link") != name or o is None:
                continue
            xyz = _vec(o.get("xyz"))
            if np.linalg.norm(xyz) > 1e-9:
                offsets.append(xyz)
                o.set("xyz", _fmt(xyz * s))
        if not offsets:
            raise ValueError(f"link {name!r} has no child joint at an offset")
        u = offsets[0] / np.linalg.norm(offsets[0])
        for part in links[name].findall("visual") + links[name].findall("collision"):
            o = part.find("origin")
            if o is None:
                o = ET.SubElement(part, "origin")
            xyz, rot = _vec(o.get("xyz")), _rpy_matrix(_vec(o.get("rpy")))
            o.set("xyz", _fmt(xyz + (s - 1.0) * float(xyz @ u) * u))
            local = np.abs(rot.T @ u)  # the stretch direction in the shape's own frame
            stretch = 1.0 + (s - 1.0) * local
            g = part.find("geometry")
            shape = g[0] if g is not None and len(g) else None
            if shape is None:
                continue
            if shape.tag == "mesh":
                shape.set("scale", _fmt(_vec(shape.get("scale"), 1.0) * stretch))
            elif shape.tag == "box":
                shape.set("size", _fmt(_vec(shape.get("size")) * stretch))
            elif shape.tag == "cylinder" and local[2] > 0.9:
                shape.set("length", f"{float(shape.get('length', '0')) * s:.9g}")
    return ET.tostring(root, encoding="unicode")


class ArmWorld(World):
    """A robot arm from a URDF: the camera image in, joint increments out.

    Parameters
    ----------
    world_id : str, default="arm"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (random starts).
    params : ArmWorldParams or None, default=None
        The parameters (default: `ArmWorldParams()`).
    **overrides
        Parameter values applied over `params`, checked by `protocol.params.parse`.

    Raises
    ------
    ParamError
        A URDF that cannot be loaded, a joint or link it does not have (the message names the valid
        ones), or a lattice that does not fit a joint's limits.

    Examples
    --------
    >>> import numpy as np
    >>> with ArmWorld(seed=0, lattice=3) as w:
    ...     r = w.reset(start=0)
    ...     r = w.step(np.array([0.0]))  # first moving joint +step
    """

    kind = "arm"
    Params: ClassVar[type] = ArmWorldParams
    Perturbations: ClassVar[dict[str, type]] = {
        "morph": MorphParams,
        "lesion": JointParams,
        "reverse": ReverseParams,
        "gain": GainParams,
        "heal": HealParams,
    }

    def __init__(
        self, world_id: str = "arm", seed: int = 0, params: ArmWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(ArmWorldParams, overrides, name=self.kind, base=params)
        self.urdf = resolve_urdf(prm.urdf)
        with open(self.urdf, encoding="utf-8") as f:
            self._urdf_text = f.read()
        try:
            self._root = ET.fromstring(self._urdf_text)
        except ET.ParseError as e:
            raise ParamError(f"arm: {self.urdf} is not a URDF (XML: {e})") from None
        self._tmp: str | None = None
        self._scales: dict[str, float] = {}
        self._c: Any = direct_client()
        try:
            self._setup()
        except BaseException:
            self.close()
            raise

    # set-up --------------------------------------------------------------------------------------
    def _load(self, path: str) -> int:
        try:
            return self._c.loadURDF(path, useFixedBase=True, flags=p.URDF_USE_MATERIAL_COLORS_FROM_MTL)
        except p.error:
            raise ParamError(f"arm: PyBullet cannot load the URDF {path!r}") from None

    def _setup(self) -> None:
        prm = self.params
        self.body = self._load(self.urdf)
        c = self._c
        info = [c.getJointInfo(self.body, i) for i in range(c.getNumJoints(self.body))]
        self.joint_names = [i[1].decode() for i in info]
        self.link_names = [i[12].decode() for i in info]
        movable = [i[0] for i in info if i[2] in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC)]
        self.movable_names = [self.joint_names[i] for i in movable]
        revolute = [i for i in movable if info[i][2] == p.JOINT_REVOLUTE]
        if not revolute:
            raise ParamError(f"arm: {self.urdf} has no revolute joint")
        self._limits = {}
        for i in movable:
            lo, hi = float(info[i][8]), float(info[i][9])
            if hi <= lo:  # no limits declared (continuous)
                lo, hi = -math.pi, math.pi
            self._limits[i] = (lo, hi)
        self.rest = {i: float(np.clip(0.0, *self._limits[i])) for i in movable}
        self.hand = self._hand_link(info, revolute)
        if prm.joints:
            names = self.movable_names
            bad = [j for j in prm.joints if j not in names]
            if bad:
                raise ParamError(
                    f"arm: no movable joint {bad[0]!r} in {os.path.basename(self.urdf)}; valid: {', '.join(names)}"
                )
            self.moving = [self.joint_names.index(j) for j in prm.joints]
        else:
            self.moving = self._most_moving(revolute, prm.n_joints)
        n = len(self.moving)
        for i in self.moving:  # the lattice's centre: the moving joints bent, not at a straight singular pose
            self.rest[i] = float(np.clip(prm.bend, *self._limits[i]))
        self._grid = []
        for i in self.moving:
            lo, hi = self._limits[i]
            span = prm.step * (prm.lattice - 1)
            if span > hi - lo + 1e-9:
                raise ParamError(
                    f"arm: joint {self.joint_names[i]} spans {hi - lo:.3f} rad, the lattice {span:.3f} "
                    f"({prm.lattice} x {prm.step} rad); lower `lattice` or `step`"
                )
            start = self.rest[i] - span / 2
            start = min(max(start, lo), hi - span)
            self._grid.append(np.round(start + prm.step * np.arange(prm.lattice), 9) + 0.0)
        self.proprioception = prm.proprioception if prm.proprioception is not None else n > 4
        self.goal_steps = prm.goal_steps if prm.goal_steps is not None else (1 if n > 4 else 0)
        lattice_size = prm.lattice**n
        self.sampled = (prm.starts > 0 or n > 4) and (prm.starts or 128) < lattice_size
        if self.sampled:
            self.poses = self._sample_poses(prm.starts or 128)
        else:
            mesh = np.meshgrid(*self._grid, indexing="ij")
            self.poses = np.stack([m.reshape(-1) for m in mesh], axis=1)  # [lattice^n, n]
        self._centre = np.array([g[len(g) // 2] for g in self._grid])  # the lattice's centre pose
        self._lo = np.array([g[0] for g in self._grid]) - 1e-9
        self._hi = np.array([g[-1] for g in self._grid]) + 1e-9
        self.max_episode_steps = prm.max_episode_steps or 4 * n * (prm.lattice - 1)
        self.sign = np.ones(n)
        self.gain = np.ones(n)
        self.locked: dict[int, float] = {}  # moving-joint index -> angle it is held at
        self.angles = self.poses[0].copy()
        self.t = 0
        self._goal: np.ndarray | None = None
        self._views: OrderedDict[tuple[float, ...], np.ndarray] = OrderedDict()
        self._frame: np.ndarray | None = None
        self._marker = -1
        self._place_camera()
        self.marker_colour = self._pick_colour()
        vis = self._c.createVisualShape(p.GEOM_SPHERE, radius=prm.marker, rgbaColor=[*self.marker_colour, 1.0])
        self._marker = self._c.createMultiBody(0, baseVisualShapeIndex=vis)

    def _sample_poses(self, k: int) -> np.ndarray:
        """`k` distinct lattice poses drawn at random (seeded by the world's seed, in draw order)."""
        rng = np.random.default_rng([self.seed, 36])
        n, m = len(self._grid), self.params.lattice
        picked: dict[tuple[int, ...], None] = {}
        while len(picked) < k:
            for row in rng.integers(0, m, (k, n)):
                picked.setdefault(tuple(int(v) for v in row), None)
                if len(picked) == k:
                    break
        idx = np.array(list(picked))
        return np.stack([self._grid[j][idx[:, j]] for j in range(n)], axis=1)

    def _hand_link(self, info: list[Any], movable: list[int]) -> int:
        if self.params.hand:
            if self.params.hand not in self.link_names:
                raise ParamError(f"arm: no link {self.params.hand!r}; valid: {', '.join(self.link_names)}")
            return self.link_names.index(self.params.hand)
        hand = movable[-1]
        while True:  # follow fixed joints past the last movable one (the flange, the hand)
            nxt = [i[0] for i in info if i[16] == hand and i[2] == p.JOINT_FIXED]
            if not nxt:
                return hand
            hand = nxt[0]

    def _set_body(self, angles: np.ndarray) -> None:
        for i, r in self.rest.items():
            self._c.resetJointState(self.body, i, r)
        for i, a in zip(self.moving, angles, strict=True):
            self._c.resetJointState(self.body, i, float(a))

    def hand_position(self, angles: np.ndarray) -> np.ndarray:
        """The hand link's world position (m) with the moving joints at `angles`."""
        self._set_body(angles)
        st = self._c.getLinkState(self.body, self.hand, computeForwardKinematics=True)
        return np.array(st[4], dtype=np.float64)

    def tip_position(self, angles: np.ndarray) -> np.ndarray:
        """Where the marker rides: just past the hand, along the line from the last moving joint's
        link to the hand (the end of the arm as the camera sees it)."""
        hand = self.hand_position(angles)
        st = self._c.getLinkState(self.body, self.moving[-1], computeForwardKinematics=True)
        u = hand - np.array(st[4])
        norm = float(np.linalg.norm(u))
        return hand + (1.5 * self.params.marker / norm) * u if norm > 1e-9 else hand

    def _most_moving(self, movable: list[int], n: int) -> list[int]:
        if n > len(movable):
            raise ParamError(f"arm: n_joints {n}, but {os.path.basename(self.urdf)} has {len(movable)} movable joints")
        rest = np.array([self.rest[i] for i in movable])
        self.moving = movable
        h0 = self.hand_position(rest)
        moved = []
        for k in range(len(movable)):
            a = rest.copy()
            a[k] += 0.1 if rest[k] + 0.1 <= self._limits[movable[k]][1] else -0.1
            moved.append(float(np.linalg.norm(self.hand_position(a) - h0)))
        pick = sorted(np.argsort(moved)[::-1][:n])  # the n largest, in chain order
        return [movable[k] for k in pick]

    def _place_camera(self) -> None:
        prm = self.params
        hands = np.array([self.tip_position(q) for q in self.poses])
        centre = self.tip_position(self._centre if self.sampled else self.poses[len(self.poses) // 2])
        _, _, vt = np.linalg.svd(hands - hands.mean(axis=0), full_matrices=True)
        axis = vt[-1] if len(hands) > 2 else np.array([1.0, 0.0, 0.0])
        if abs(axis[2]) > 0.9:  # looking down: keep the view's up axis horizontal
            up = [0.0, 1.0, 0.0]
        else:
            up = [0.0, 0.0, 1.0]
        if axis @ np.array([1.0, 0.3, 0.1]) < 0:
            axis = -axis
        radius = float(np.max(np.linalg.norm(hands - centre, axis=1))) + 2 * prm.marker
        dist = 1.25 * radius / math.tan(math.radians(prm.fov) / 2) + prm.marker
        self.camera_eye = centre + dist * axis
        self.camera_target = centre
        self._light = (dist * axis).tolist()  # from the camera's side: the faces it sees are lit
        self._view = self._c.computeViewMatrix(self.camera_eye.tolist(), centre.tolist(), up)
        self._proj = self._c.computeProjectionMatrixFOV(prm.fov, 1.0, 0.01, dist + 4 * radius + 2.0)

    def _pick_colour(self) -> tuple[float, float, float]:
        """The first marker colour that the robot alone shows nowhere (corners and centre of the lattice)."""
        if self.sampled:
            corners = [np.array([g[0] for g in self._grid]), np.array([g[-1] for g in self._grid]), self._centre]
        else:
            corners = [self.poses[0], self.poses[-1], self.poses[len(self.poses) // 2]]
        views = [self.render(q, self.params.goal_image) for q in corners]
        for colour in MARKER_COLOURS:
            if not any(colour_mask(v, colour).any() for v in views):
                return colour
        raise ParamError(f"arm: every marker colour is also a colour of {os.path.basename(self.urdf)}")

    # rendering -----------------------------------------------------------------------------------
    def render(self, angles: np.ndarray, size: int) -> np.ndarray:
        """The camera's RGB view (float64 in [0, 1], size x size x 3) with the moving joints at `angles`."""
        if self._marker >= 0:
            self._c.resetBasePositionAndOrientation(self._marker, self.tip_position(angles).tolist(), [0, 0, 0, 1])
        else:
            self._set_body(angles)
        _, _, rgba, _, _ = self._c.getCameraImage(
            size,
            size,
            self._view,
            self._proj,
            shadow=0,
            lightDirection=self._light,
            renderer=p.ER_TINY_RENDERER,
            flags=p.ER_NO_SEGMENTATION_MASK,
        )
        return np.asarray(rgba, dtype=np.float64).reshape(size, size, 4)[..., :3] / 255.0

    def observe(self, angles: np.ndarray) -> np.ndarray:
        """The grey observation at `angles` (float32, image x image; kept for repeated poses)."""
        key = tuple(np.round(angles, 9).tolist())
        img = self._views.get(key)
        if img is None:
            rgb = self.render(angles, self.params.image)
            img = (rgb @ np.array([0.2125, 0.7154, 0.0721])).astype(np.float32)
            img.flags.writeable = False
            self._views[key] = img
            if len(self._views) > _CACHE:
                self._views.popitem(last=False)
        else:
            self._views.move_to_end(key)
        return img

    def marker_position(self, angles: np.ndarray) -> np.ndarray | None:
        """Where the marker is seen in the goal-size colour image (column, row, px), or None when
        no pixel of it is visible: the pixels that are green and little else."""
        mask = colour_mask(self.render(angles, self.params.goal_image), self.marker_colour)
        if not mask.any():
            return None
        rows, cols = np.nonzero(mask)
        return np.array([cols.mean(), rows.mean()])

    # the perceptual goal -------------------------------------------------------------------------
    def _reachable(self) -> np.ndarray:
        poses = self.poses.copy()
        for k, a in self.locked.items():
            poses[:, k] = a
        return poses

    @property
    def goal(self) -> np.ndarray:
        """The reachable lattice pose whose image shows the marker nearest the image centre (found
        on first use and after a body change)."""
        if self._goal is None:
            centre = (self.params.goal_image - 1) / 2
            best, best_d = None, math.inf
            for q in np.unique(self._reachable(), axis=0):
                m = self.marker_position(q)
                if m is not None and (d := float(np.hypot(*(m - centre)))) < best_d - 1e-9:
                    best, best_d = q, d
            if best is None:
                raise RuntimeError("arm: the marker is not visible from any start pose")
            self._goal = best
        return self._goal

    def at_goal(self, angles: np.ndarray) -> bool:
        """Every moving joint within `goal_steps` steps and a half (current steps) of the goal pose."""
        tol = self.params.step * np.maximum(self.gain, 1.0) * (self.goal_steps + 0.5) + 1e-9
        return bool(np.all(np.abs(angles - self.goal) <= tol))

    # World interface -----------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """Sensor ``camera`` (and ``joints`` with proprioception); 2 actions per moving joint or a Box."""
        prm = self.params
        n = len(self.moving)
        sensors = [SensorSpec("camera", "float32", (prm.image, prm.image), 0, 1, "grey camera image of the arm")]
        if self.proprioception:
            lo = float(min(g[0] for g in self._grid))
            hi = float(max(g[-1] for g in self._grid))
            sensors.append(SensorSpec("joints", "float32", (n,), lo, hi, "the moving joints' angles, rad"))
        names = tuple(self.joint_names[i] for i in self.moving)
        if prm.actions == "box":
            space = ActionSpace(low=(-1.0,) * n, high=(1.0,) * n, names=names)
        else:
            space = ActionSpace(n=2 * n, names=tuple(f"{j}{s}" for j in names for s in ("+", "-")))
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=tuple(sensors),
            action_space=space,
            reward_min=0.0,
            reward_max=1.0,
            program="generic",
            n_starts=len(self.poses),
            params={
                "urdf": os.path.basename(self.urdf),
                "joints": ",".join(names),
                "hand": self.link_names[self.hand],
                "step_rad": repr(self.params.step),
                "max_episode_steps": str(self.max_episode_steps),
                "truth_dims": str(n),
                "starts": "sampled" if self.sampled else "lattice",
                "goal_steps": str(self.goal_steps),
            },
            goal="reward",
        )

    def _obs(self, reward: float, done: bool, truncated: bool = False) -> StepResult:
        img = self.observe(self.angles)
        self._frame = (img * 255).astype(np.uint8)
        tensors = {"camera": img}
        if self.proprioception:
            tensors["joints"] = self.angles.astype(np.float32)
        return StepResult(tensors, reward, done, truncated=truncated)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Move the arm to lattice pose `start` (in `truth` order) or a random one; ``done`` at once on the goal."""
        start = self.pick_start(seed, start, len(self.poses))
        self.angles = self._reachable()[start].copy()
        self.t = 0
        at = self.at_goal(self.angles)
        return self._obs(1.0 if at else 0.0, at)

    def step(self, action: np.ndarray) -> StepResult:
        """Move the moving joints by one increment; a move out of the lattice's range is not made."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        n = len(self.moving)
        delta = np.zeros(n)
        if self.params.actions == "box":
            if a.size != n or not np.all(np.isfinite(a)):
                raise ValueError(f"action must be {n} finite values, got {a.size}")
            delta = np.clip(a, -1.0, 1.0)
        else:
            k = int(a[0]) if a.size else -1
            if not 0 <= k < 2 * n or a[0] != k:
                raise ValueError(f"action {a[0] if a.size else None} out of range 0..{2 * n - 1}")
            delta[k // 2] = 1.0 if k % 2 == 0 else -1.0
        delta *= self.params.step * self.sign * self.gain
        for k in self.locked:
            delta[k] = 0.0
        nxt = np.round(self.angles + delta, 9) + 0.0  # on the lattice: no drift in the low bits, no -0.0
        if np.all(nxt >= self._lo) and np.all(nxt <= self._hi):
            self.angles = nxt
        self.t += 1
        at = self.at_goal(self.angles)
        out = self.t >= self.max_episode_steps and not at
        return self._obs(1.0 if at else 0.0, at or out, truncated=out)

    def truth(self) -> Truth:
        """The moving joints' angles of every start state (``positions``, rad) and the hand's 3-D
        position there (``hand``, m), for the body as it is now; row i for start state i."""
        poses = self._reachable()
        hands = np.array([self.hand_position(q) for q in poses])
        self._set_body(self.angles)
        return Truth(self.world_id, "start_states", {"positions": poses.astype(np.float64), "hand": hands})

    def frame(self) -> np.ndarray | None:
        """The latest observation as uint8 grey."""
        return self._frame

    # body changes --------------------------------------------------------------------------------
    def _joint(self, name: str) -> int:
        names = [self.joint_names[i] for i in self.moving]
        if not name:
            return 0
        if name not in names:
            raise PerturbationError(f"arm has no moving joint {name!r}; valid: {', '.join(names)}")
        return names.index(name)

    def _changed(self) -> None:
        self._goal = None
        self._views.clear()

    def _reload(self) -> None:
        if self._scales:
            if self._tmp is None:
                self._tmp = tempfile.mkdtemp(prefix="sme-arm-")
            text = morph_urdf(self._urdf_text, os.path.dirname(self.urdf), self._scales)
            path = os.path.join(self._tmp, "morphed.urdf")
            with open(path, "w", encoding="utf-8") as f:
                f.write(text)
        else:
            path = self.urdf
        self._c.removeBody(self.body)
        self.body = self._load(path)
        self._set_body(self.angles)
        self._changed()

    def perturb(self, control: Control) -> str:
        """Apply `morph`, `lesion`, `reverse`, `gain` or `heal`; refuse a bad one before changing anything."""
        prm = self.perturbation_params(control)
        if isinstance(prm, MorphParams):
            valid = scalable_links(self._root)
            link = prm.link or self.link_names[self.moving[0]]
            if link not in valid:
                raise PerturbationError(f"arm: morph cannot scale link {link!r}; valid: {', '.join(valid)}")
            self._scales[link] = self._scales.get(link, 1.0) * prm.scale
            self._reload()
            return f"morph: link {link} x {prm.scale} (now x {self._scales[link]:.3g} of the original)"
        if isinstance(prm, JointParams):
            k = self._joint(prm.joint)
            name = self.joint_names[self.moving[k]]
            if k in self.locked:
                del self.locked[k]
                self._changed()
                return f"lesion: joint {name} moves again"
            if prm.at is not None and not self._lo[k] <= prm.at <= self._hi[k]:
                raise PerturbationError(
                    f"arm: lesion at {prm.at} rad is outside joint {name}'s range {self._lo[k]:.3f}..{self._hi[k]:.3f}"
                )
            self.angles[k] = self.angles[k] if prm.at is None else prm.at
            self.locked[k] = float(self.angles[k])
            self._set_body(self.angles)
            self._changed()
            return f"lesion: joint {name} locked at {self.angles[k]:.3f} rad"
        if isinstance(prm, ReverseParams):
            k = self._joint(prm.joint)
            self.sign[k] *= -1
            name = self.joint_names[self.moving[k]]
            return f"reverse: joint {name} commands {'flipped' if self.sign[k] < 0 else 'restored'}"
        if isinstance(prm, GainParams):
            k = self._joint(prm.joint)
            self.gain[k] = prm.gain
            return f"gain: joint {self.joint_names[self.moving[k]]} step x {prm.gain}"
        self.sign[:] = 1.0
        self.gain[:] = 1.0
        self.locked.clear()
        if self._scales:
            self._scales.clear()
            self._reload()
        self._changed()
        return "heal: the body, its joints and their commands as they started"

    def close(self) -> None:
        """Disconnect the PyBullet client and remove the rewritten URDFs."""
        disconnect(self._c)
        self._c = None
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None


__all__ = ["ArmWorld", "ArmWorldParams", "morph_urdf", "resolve_urdf", "scalable_links"]
