"""The arm world's parameters and those of its body changes: typed, defaulted, documented
declarations (`--param KEY=V`, `sme perturb arm KIND KEY=V`), listed in docs/worlds.md."""

from __future__ import annotations

from dataclasses import dataclass

from sensorimotor.protocol.params import option


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
