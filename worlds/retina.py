"""Foveated retina on a pan/tilt camera (ch. 4, Fig 4.1), rendered headless with PyBullet.

A pinhole camera at the origin faces a dark wall with a bright spot (the salient target; options:
several spots, or a textured wall). The retina has `layers` layers of `fields` x `fields` receptive
fields, all centred; fields in the largest layer are `field_px` retina pixels wide and halve per
layer (default 4 layers of 32x32 over 128x128 px: 4, 2, 1, 0.5 px). Each layer is rendered with its
own narrowed field of view at `supersample`^2 samples per field, so every field reports the
normalised mean of its own patch at its own resolution. Fields are published in a fixed shuffled
order: the agent is never told where a field is.

Actions are saccades in motor units (degrees of pan, degrees of tilt). Episodes are ballistic:
a random reposition (t = 0, reward 0), one saccade, reward = total activation after it (Eq 4.1),
done. Truth: each field's position in action units, defined as minus the saccade that brings a
point seen at the field's centre to the retina centre (so learned positions -pi_k compare directly).
Perturbations: lesion (fields in a disc read 0), reverse (up/down motor commands swapped), noise
(additive sensor noise), heal (undo all).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pybullet as p

from sensorimotor.protocol.messages import ActionSpace, Control, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import HealParams, StepResult, World
from sensorimotor.worlds.bullet import direct_client, disconnect

SCENES = ("spot", "spots", "texture")


def field_layout(layers: int, fields: int, field_px: float) -> np.ndarray:
    """Centres (u right, v up; retina px from the centre) and sizes of all fields, layer by layer,
    row by row (top first): an array [n, 3] of (u, v, size)."""
    out = []
    for L in range(layers):
        size = field_px / 2**L
        c = (np.arange(fields) - (fields - 1) / 2) * size
        vv, uu = np.meshgrid(-c, c, indexing="ij")  # row r has v = -c[r]: top row first
        out.append(np.stack([uu.ravel(), vv.ravel(), np.full(uu.size, size)], axis=1))
    return np.concatenate(out)


@dataclass(frozen=True)
class RetinaWorldParams:
    """Parameters of the foveated retina on a pan/tilt camera (Fig 4.1)."""

    layers: int = option(4, "retina layers; field size halves per layer", min=1)
    fields: int = option(32, "receptive fields per layer side", min=2)
    field_px: float = option(4.0, "width of a field in the largest layer, retina px (> 0)")
    fov_deg: float = option(30.0, "field of view of the largest layer, degrees, in (0, 120)")
    scene: str = option("spot", "what the wall shows", choices=SCENES)
    spot_px: float = option(6.0, "spot diameter seen straight on, retina px", min=0.0)
    n_spots: int = option(3, "number of spots for scene=spots", min=1)
    reposition_px: float = option(48.0, "random reposition before each saccade, up to this many px", min=0.0)
    max_saccade_deg: float = option(16.0, "largest saccade per axis, degrees", min=0.0)
    supersample: int = option(2, "render samples per field side (1 is ~3x faster)", min=1)
    wall_distance: float = option(5.0, "distance from the camera to the wall, m")


@dataclass(frozen=True)
class LesionParams:
    """Fields whose centre lies within `radius` px of (`u`, `v`) read 0 from now on (lesions add up)."""

    u: float = option(6.0, "lesion centre, retina px right of the retina centre", min=-512.0, max=512.0)
    v: float = option(0.0, "lesion centre, retina px up from the retina centre", min=-512.0, max=512.0)
    radius: float = option(6.0, "lesion radius, retina px", min=0.0, max=512.0)


@dataclass(frozen=True)
class ReverseParams:
    """Swap the up/down motor commands (a second reverse restores them)."""


@dataclass(frozen=True)
class NoiseParams:
    """Additive Gaussian sensor noise on every field (activations are in 0..1); replaces earlier noise."""

    sd: float = option(0.05, "standard deviation of the noise (0 turns it off)", min=0.0, max=1.0)


class RetinaWorld(World):
    """A foveated retina on a pan/tilt camera (Fig 4.1): field activations in, a saccade out.

    Episodes are ballistic: a random reposition, one saccade (degrees of pan and tilt), reward =
    total activation after it, done. The agent learns where each field is from that alone.

    Parameters
    ----------
    world_id : str, default="retina"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (repositions, noise).
    params : RetinaWorldParams or None, default=None
        The parameters (default: `RetinaWorldParams()`).
    **overrides
        Parameter values applied over `params` (``k=v`` strings or typed values), checked by
        `protocol.params.parse`.

    Examples
    --------
    >>> import numpy as np
    >>> with RetinaWorld(seed=0) as w:
    ...     r = w.reset()
    ...     r = w.step(np.array([2.0, -1.0]))  # pan 2 degrees right, tilt 1 down
    ...     reward = r.reward
    """

    kind = "retina"
    max_episode_steps = 1
    Params = RetinaWorldParams
    Perturbations = {"lesion": LesionParams, "reverse": ReverseParams, "noise": NoiseParams, "heal": HealParams}

    def __init__(
        self, world_id: str = "retina", seed: int = 0, params: RetinaWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(RetinaWorldParams, overrides, name=self.kind, base=params)
        layers, fields, field_px, fov_deg = prm.layers, prm.fields, prm.field_px, prm.fov_deg
        scene, spot_px, n_spots, reposition_px = prm.scene, prm.spot_px, prm.n_spots, prm.reposition_px
        max_saccade_deg, supersample, wall_distance = prm.max_saccade_deg, prm.supersample, prm.wall_distance
        if field_px <= 0:
            raise ValueError(f"retina: field_px={field_px} must be > 0")
        if not 0 < fov_deg < 120:
            raise ValueError(f"retina: fov_deg={fov_deg} must be in (0, 120)")
        self.layers, self.fields, self.field_px = layers, fields, field_px
        self.supersample = supersample
        self.retina_px = fields * field_px
        self.focal = (self.retina_px / 2) / math.tan(math.radians(fov_deg) / 2)  # px
        self.fov_deg = fov_deg
        self.scene = scene
        self.reposition_px = reposition_px
        self.max_saccade = max_saccade_deg
        self.wall = wall_distance
        self.layout = field_layout(layers, fields, field_px)
        self.n = self.layout.shape[0]
        # published order: fixed shuffle; order[i] = layout index of published field i
        self.order = np.random.default_rng(20_000 + seed).permutation(self.n)
        self.centres = self.layout[self.order, :2]
        self.pan = self.tilt = 0.0
        self.reversed = False
        self.noise_sd = 0.0
        self.lesion = np.zeros(self.n, dtype=bool)
        self._client = direct_client()
        self._spot_world: list[np.ndarray] = []
        self._build_scene(spot_px, n_spots)
        res = fields * supersample
        self._proj = [
            self._client.computeProjectionMatrixFOV(
                math.degrees(2 * math.atan(math.tan(math.radians(fov_deg) / 2) / 2**L)), 1.0, 0.1, 2 * wall_distance
            )
            for L in range(layers)
        ]
        self._res = res
        self._frame: np.ndarray | None = None

    # scene -------------------------------------------------------------------------------------
    def _build_scene(self, spot_px: float, n_spots: int) -> None:
        c = self._client
        half = self.wall * 1.5
        colour = [1, 1, 1, 1] if self.scene == "texture" else [0, 0, 0, 1]
        wall_vis = c.createVisualShape(p.GEOM_BOX, halfExtents=[0.01, half, half], rgbaColor=colour)
        wall = c.createMultiBody(0, baseVisualShapeIndex=wall_vis, basePosition=[self.wall + 0.01, 0, 0])
        if self.scene == "texture":
            import os

            import pybullet_data

            tex = c.loadTexture(os.path.join(pybullet_data.getDataPath(), "checker_grid.jpg"))
            c.changeVisualShape(wall, -1, textureUniqueId=tex)
            return
        radius = self.wall * spot_px / self.focal  # spot_px retina pixels wide when seen straight on
        k = 1 if self.scene == "spot" else n_spots
        rng = np.random.default_rng(30_000 + self.seed)
        for i in range(k):
            yz = np.zeros(2) if i == 0 else rng.uniform(-1, 1, 2) * self.wall * 0.25
            pos = np.array([self.wall - 0.002, yz[0], yz[1]])
            vis = c.createVisualShape(
                p.GEOM_CYLINDER,
                radius=radius,
                length=0.002,
                rgbaColor=[1, 1, 1, 1],
                visualFrameOrientation=c.getQuaternionFromEuler([0, math.pi / 2, 0]),
            )
            c.createMultiBody(0, baseVisualShapeIndex=vis, basePosition=pos.tolist())
            self._spot_world.append(pos)

    def _direction(self, pan: float, tilt: float) -> np.ndarray:
        pr, tr = math.radians(pan), math.radians(tilt)
        return np.array([math.cos(tr) * math.cos(pr), -math.cos(tr) * math.sin(pr), math.sin(tr)])

    def _basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        fwd = self._direction(self.pan, self.tilt)
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        return fwd, right, up

    def render(self) -> np.ndarray:
        """Activations of all fields in published order, with lesion and noise applied."""
        c = self._client
        fwd, _, up = self._basis()
        view = c.computeViewMatrix([0, 0, 0], (fwd * self.wall).tolist(), up.tolist())
        ss, f = self.supersample, self.fields
        acts = []
        for L in range(self.layers):
            _, _, rgb, _, _ = c.getCameraImage(
                self._res,
                self._res,
                view,
                self._proj[L],
                shadow=0,
                renderer=p.ER_TINY_RENDERER,
                flags=p.ER_NO_SEGMENTATION_MASK,
            )
            img = np.asarray(rgb, dtype=np.float32).reshape(self._res, self._res, 4)[..., :3].mean(axis=2) / 255.0
            if L == 0:
                self._frame = img
            acts.append(img.reshape(f, ss, f, ss).mean(axis=(1, 3)).ravel())
        a = np.concatenate(acts)[self.order]
        if self.noise_sd > 0:
            a = a + self.rng.normal(0.0, self.noise_sd, a.shape)
        a[self.lesion] = 0.0
        return np.clip(a, 0.0, 1.0).astype(np.float32)

    def frame(self) -> np.ndarray | None:
        """What the outermost layer sees (the whole 128-px retina), as 8-bit grey."""
        return None if self._frame is None else (self._frame * 255).astype(np.uint8)

    def target_offset_px(self, index: int = 0) -> np.ndarray:
        """Where spot `index` is seen, in retina px from the centre (u right, v up)."""
        fwd, right, up = self._basis()
        d = self._spot_world[index]
        z = float(d @ fwd)
        return np.array([self.focal * float(d @ right) / z, self.focal * float(d @ up) / z])

    def _look_at_offset(self, u: float, v: float) -> None:
        """Point the camera so that spot 0 is seen near retina offset (u, v)."""
        d = self._spot_world[0] if self._spot_world else np.array([self.wall, 0.0, 0.0])
        sp = math.degrees(math.atan2(-d[1], d[0]))
        st = math.degrees(math.atan2(d[2], math.hypot(d[0], d[1])))
        du, dv = self.saccade_for(u, v)
        self.pan, self.tilt = sp - du, st - dv

    def saccade_for(self, u: float | np.ndarray, v: float | np.ndarray) -> np.ndarray:
        """The (pan, tilt) saccade, in degrees, that centres a point seen at retina offset (u, v)
        from straight-ahead; exact for a level camera."""
        pan = np.degrees(np.arctan2(u, self.focal))
        tilt = np.degrees(np.arctan2(v, np.hypot(self.focal, u)))
        return np.stack([pan, tilt], axis=-1)

    # World interface ---------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """One float32 sensor ``fields`` (every receptive field, shuffled order), a 2-d saccade box."""
        m = self.max_saccade
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(
                SensorSpec(
                    "fields", "float32", (self.n,), 0.0, 1.0, "receptive-field activations in a fixed shuffled order"
                ),
            ),
            action_space=ActionSpace(low=(-m, -m), high=(m, m), names=("pan_deg", "tilt_deg")),
            reward_min=0.0,
            reward_max=float(self.n),
            program="retina",
            n_starts=0,
            params={
                "layers": str(self.layers),
                "fields": str(self.fields),
                "field_px": str(self.field_px),
                "scene": self.scene,
                "fov_deg": str(self.fov_deg),
            },
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Point the camera at a random offset from the target (`start` is ignored: starts are random)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        u, v = self.rng.uniform(-self.reposition_px, self.reposition_px, 2)
        self._look_at_offset(u, v)
        return StepResult({"fields": self.render()}, 0.0, False)

    def step(self, action: np.ndarray) -> StepResult:
        """One saccade ``(pan, tilt)`` in degrees (clipped); reward = total activation; always done."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.isfinite(a).all():
            raise ValueError(f"a saccade is 2 finite numbers (pan, tilt), got {a.tolist()}")
        a = np.clip(a, -self.max_saccade, self.max_saccade)
        self.pan += a[0]
        self.tilt += -a[1] if self.reversed else a[1]
        self.tilt = float(np.clip(self.tilt, -80, 80))
        fields = self.render()
        return StepResult({"fields": fields}, float(fields.sum(dtype=np.float64)), True)

    def perturb(self, control: Control) -> str:
        prm = self.perturbation_params(control)  # refuses a bad control before anything changes
        if isinstance(prm, LesionParams):
            u, v, r = prm.u, prm.v, prm.radius
            hit = np.hypot(self.centres[:, 0] - u, self.centres[:, 1] - v) <= r
            self.lesion |= hit
            return f"lesion: {int(hit.sum())} fields within {r} px of ({u}, {v}) px now read 0"
        if isinstance(prm, ReverseParams):
            self.reversed = not self.reversed
            return f"reverse: up/down motor commands {'swapped' if self.reversed else 'restored'}"
        if isinstance(prm, NoiseParams):
            self.noise_sd = prm.sd
            return f"noise: additive sensor noise sd {self.noise_sd}"
        self.lesion[:] = False  # heal
        self.reversed = False
        self.noise_sd = 0.0
        return "heal: lesion, reversal and noise undone"

    def truth(self) -> Truth:
        """Each field's position in action units (minus the saccade that centres it; tilt flipped
        while reversed), and its centre in retina px (``pixels``).
        """
        pos = -self.saccade_for(self.centres[:, 0], self.centres[:, 1])
        if self.reversed:
            pos[:, 1] *= -1
        return Truth(self.world_id, "fields", {"positions": pos, "pixels": self.centres.copy()})

    def close(self) -> None:
        """Disconnect the PyBullet client."""
        disconnect(self._client)
        self._client = None
