"""The roving eye (ch. 5.2, Fig 5.9): a 128x128 eye that moves over a larger natural image.

The image is one of scikit-image's bundled pictures (no download), in grey, 0..1. The agent sees
only the eye's pixels. Its perceptual goals come from a gradient policy on directional filters
(`worlds.perceptual_goals`): the goal of this world is the one with the largest region of
attraction, and the start states are points of that region (`starts=region`: `n_starts` of them
drawn at random; `starts=grid`: every region point on a `grid_px` grid).

The eye may look past the image's edge (it sees black there): no move is clipped, so the reward
has no flat plateau at the edge for a learner to drift on. Moves (`moves`): `ballistic` (default) - one continuous jump (dx, dy) in px, then the episode ends
with reward exp(-distance to the goal / `reward_px`); `multistep` - 16 discrete moves of `step_px`
px, the episode ends within `goal_px` of the goal (that reward) or after `max_episode_steps`
(reward 0). Truth: the eye offset (u, v) of every start state, image px. Perturbation: `gain`
(every move becomes `gain` times longer: a different eye muscle), `heal`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, Control, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import HealParams, StepResult, World
from sensorimotor.worlds.perceptual_goals import Goals, IntensitySurface, directions, find_goals, reward

#: scikit-image's bundled pictures (shipped in the package: nothing is downloaded)
IMAGES = (
    "camera",
    "astronaut",
    "coffee",
    "brick",
    "chelsea",
    "coins",
    "grass",
    "gravel",
    "moon",
    "rocket",
    "hubble_deep_field",
)
MOVES = ("ballistic", "multistep")
STARTS = ("region", "grid")


@functools.lru_cache(maxsize=8)
def load_image(name: str) -> np.ndarray:
    """Bundled scikit-image picture `name` as grey floats in 0..1 ([H, W], read-only)."""
    if name not in IMAGES:
        raise ValueError(f"unknown image {name!r}; one of {', '.join(IMAGES)}")
    import skimage.data
    from skimage.color import rgb2gray

    img = getattr(skimage.data, name)()
    if img.ndim == 3:
        img = rgb2gray(img[..., :3])
    img = np.asarray(img, dtype=np.float64)
    img = (img - img.min()) / max(float(img.max() - img.min()), 1e-12)
    img.setflags(write=False)
    return img


def eye_view(image: np.ndarray, pos: np.ndarray, eye_px: int) -> np.ndarray:
    """The eye's pixels [eye_px, eye_px] centred at `pos` (u, v), rounded to whole pixels; where
    the eye looks past the image's edge it sees black."""
    h = eye_px // 2
    u, v = int(round(float(pos[0]))) - h, int(round(float(pos[1]))) - h
    H, W = image.shape
    if 0 <= u and u + eye_px <= W and 0 <= v and v + eye_px <= H:
        return image[v : v + eye_px, u : u + eye_px]
    out = np.zeros((eye_px, eye_px), dtype=image.dtype)
    r0, r1, c0, c1 = max(v, 0), min(v + eye_px, H), max(u, 0), min(u + eye_px, W)
    if r0 < r1 and c0 < c1:
        out[r0 - v : r1 - v, c0 - u : c1 - u] = image[r0:r1, c0:c1]
    return out


def eye_bounds(image: np.ndarray, eye_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest eye centre (u, v) that keep the whole eye on the image (where goals and
    start states are looked for; moves may take the eye past them)."""
    h = eye_px // 2
    H, W = image.shape
    if H < eye_px + 2 or W < eye_px + 2:
        raise ValueError(f"image {W}x{H} is too small for a {eye_px}-px eye")
    return np.array([h, h], dtype=np.float64), np.array([W - eye_px + h, H - eye_px + h], dtype=np.float64)


@functools.lru_cache(maxsize=8)
def image_goals(image: str, eye_px: int, sigma: float, grid_px: float, step_px: float) -> Goals:
    """The perceptual goals of bundled image `image` (cached: the same for every seed)."""
    img = load_image(image)
    lo, hi = eye_bounds(img, eye_px)
    return find_goals(IntensitySurface.of(img, sigma), lo, hi, grid_px=grid_px, step_px=step_px)


@dataclass(frozen=True)
class RovingEyeParams:
    """Parameters of the roving eye (ch. 5.2)."""

    image: str = option("camera", "bundled scikit-image picture the eye moves over", choices=IMAGES)
    eye_px: int = option(128, "side of the square eye, px", min=8)
    moves: str = option("ballistic", "one continuous jump per episode, or 16 discrete moves", choices=MOVES)
    step_px: float = option(5.0, "length of a discrete move, px", min=0.5)
    max_jump_px: float = option(192.0, "largest ballistic jump per axis, px", min=1.0)
    sigma_px: float = option(16.0, "scale of the directional filters (Gaussian sigma), px", min=1.0)
    grid_px: float = option(4.0, "spacing of the points the gradient policy is followed from, px", min=1.0)
    starts: str = option("region", "start states: random points of the largest goal region, or a grid", choices=STARTS)
    n_starts: int = option(100, "start states drawn from the region (starts=region)", min=3)
    start_grid_px: float = option(16.0, "grid spacing of the start states (starts=grid), px", min=1.0)
    reward_px: float = option(5.0, "reward exp(-distance / reward_px) at the end of an episode", min=0.1)
    goal_px: float = option(3.0, "multistep: an episode ends within this distance of the goal, px", min=0.0)
    max_episode_steps: int = option(100, "multistep: steps after which an episode ends with reward 0", min=1)


@dataclass(frozen=True)
class GainParams:
    """Every move becomes `gain` times longer (a different eye muscle); replaces an earlier gain."""

    gain: float = option(1.5, "move length multiplier", min=0.1, max=4.0)


class RovingEyeWorld(World):
    """A 128x128 eye over a bundled natural image (Fig 5.9): the eye's pixels in, a move out.

    Parameters
    ----------
    world_id : str, default="rovingeye"
        The world's id on the bus.
    seed : int, default=0
        Seeds the choice of start states (starts=region) and random starts.
    params : RovingEyeParams or None, default=None
        The parameters (default: `RovingEyeParams()`).
    **overrides
        Parameter values applied over `params`, checked by `protocol.params.parse`.

    Examples
    --------
    >>> import numpy as np
    >>> w = RovingEyeWorld(seed=0, n_starts=20)
    >>> r = w.reset(start=0)
    >>> r = w.step(w.goal - w.starts[0])
    >>> round(r.reward, 3)
    1.0
    """

    kind = "rovingeye"
    Params = RovingEyeParams
    Perturbations = {"gain": GainParams, "heal": HealParams}

    def __init__(
        self, world_id: str = "rovingeye", seed: int = 0, params: RovingEyeParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(RovingEyeParams, overrides, name=self.kind, base=params)
        self.image = load_image(prm.image)
        self.lo, self.hi = eye_bounds(self.image, prm.eye_px)
        self.goals = image_goals(prm.image, prm.eye_px, prm.sigma_px, prm.grid_px, prm.step_px)
        g = self.goals.largest()
        self.goal = self.goals.centres[g].copy()
        region = self.goals.region(g)
        if prm.starts == "grid":
            on = np.all(np.isclose(np.mod(region - self.lo, prm.start_grid_px), 0.0), axis=1)
            starts = region[on]
        else:
            pick = np.random.default_rng(40_000 + seed).choice(len(region), min(prm.n_starts, len(region)), False)
            starts = region[np.sort(pick)]
        if len(starts) < 3:
            raise ValueError(f"rovingeye: only {len(starts)} start states; use a smaller start_grid_px")
        self.starts = starts
        self.dirs = directions(16)
        self.max_episode_steps = prm.max_episode_steps if prm.moves == "multistep" else 1
        self.gain = 1.0
        self.pos = self.starts[0].copy()
        self.t = 0

    def spec(self) -> WorldSpec:
        """One uint8 sensor ``eye`` [eye_px, eye_px]; a 2-D jump box or 16 discrete moves."""
        prm = self.params
        if prm.moves == "ballistic":
            m = prm.max_jump_px
            space = ActionSpace(low=(-m, -m), high=(m, m), names=("dx_px", "dy_px"))
            program = "rovingeye"
        else:
            space = ActionSpace(n=16, names=tuple(f"move{k * 22.5:g}deg" for k in range(16)))
            program = "generic"
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(SensorSpec("eye", "uint8", (prm.eye_px, prm.eye_px), 0, 255, "the eye's grey pixels"),),
            action_space=space,
            reward_min=0.0,
            reward_max=1.0,
            program=program,
            n_starts=len(self.starts),
            params={"image": prm.image, "moves": prm.moves, "eye_px": str(prm.eye_px), "step_px": str(prm.step_px)},
        )

    def view(self) -> np.ndarray:
        """The eye's pixels at its current position, floats 0..1."""
        return eye_view(self.image, self.pos, self.params.eye_px)

    def frame(self) -> np.ndarray:
        """What the eye sees, 8-bit grey."""
        return (self.view() * 255).astype(np.uint8)

    def _obs(self, r: float, done: bool) -> StepResult:
        return StepResult({"eye": self.frame()}, r, done)

    def distance(self) -> float:
        """Distance from the eye to the goal, px (evaluation only)."""
        return float(np.linalg.norm(self.pos - self.goal))

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Put the eye on start state `start` (or a random one)."""
        self.pos = self.starts[self.pick_start(seed, start, len(self.starts))].copy()
        self.t = 0
        return self._obs(0.0, False)

    def step(self, action: np.ndarray) -> StepResult:
        """A ballistic jump (dx, dy) px, or discrete move ``action[0]``; the eye stays on the image."""
        prm = self.params
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if prm.moves == "ballistic":
            if a.shape != (2,) or not np.isfinite(a).all():
                raise ValueError(f"a ballistic move is 2 finite numbers (dx, dy), got {a.tolist()}")
            d = np.clip(a, -prm.max_jump_px, prm.max_jump_px)
        else:
            k = int(a[0]) if a.size and np.isfinite(a[0]) else -1
            if not 0 <= k < 16:
                raise ValueError(f"a multistep move is an index 0..15, got {a.tolist()}")
            d = prm.step_px * self.dirs[k]
        self.pos = self.pos + self.gain * d
        self.t += 1
        r = float(reward(self.distance(), prm.reward_px))
        if prm.moves == "ballistic":
            return self._obs(r, True)
        if self.distance() <= prm.goal_px:
            return self._obs(r, True)
        return self._obs(0.0, self.t >= self.max_episode_steps)

    def perturb(self, control: Control) -> str:
        prm = self.perturbation_params(control)
        if isinstance(prm, GainParams):
            self.gain = prm.gain
            return f"gain: every move is now {self.gain:g}x as long"
        self.gain = 1.0
        return "heal: move gain back to 1"

    def truth(self) -> Truth:
        """The eye offset (u, v) of every start state, image px, row i for start state i."""
        return Truth(self.world_id, "start_states", {"positions": self.starts.copy()})
