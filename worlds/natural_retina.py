"""The ch. 4 retina on a natural scene (Table 4.1): the foveated retina as a roving eye over a
bundled scikit-image picture.

As in the dissertation's natural-scene runs, the picture is blurred (5x5 Gaussian) and only its
brightest 1 % of pixels are active (1, the rest 0): the salient blobs. The retina is the ch. 4 layout
(`worlds.retina.field_layout`: 4 layers of 32x32 fields, 4, 2, 1, 0.5 px wide) over a 128-px eye;
each field reports the mean activity under it (fields under a pixel wide read the pixel they sit on).
Actions are saccades in px (u right, v up). Episodes: the eye is put within `reposition_px` of a
randomly chosen blob (the target), one saccade, reward = total activation after it, done; a
reposition with more than `max_active` active pixels in view is redrawn (the dissertation skipped
such steps). Truth: each field's position in action units (minus the saccade that centres it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.retina import field_layout
from sensorimotor.worlds.roving_eye import IMAGES, load_image


def salient(image: np.ndarray, top: float = 0.01, blur_sigma: float = 1.0) -> np.ndarray:
    """The 5x5 Gaussian blur of `image` (sigma 1 px, truncated at 2 sigma) with its brightest
    `top` fraction of pixels set to 1 and the rest to 0."""
    b = ndimage.gaussian_filter(np.asarray(image, dtype=np.float64), blur_sigma, truncate=2.0)
    return (b >= np.quantile(b, 1.0 - top)).astype(np.float32)


@dataclass(frozen=True)
class NaturalRetinaParams:
    """Parameters of the retina on a natural scene (Table 4.1)."""

    image: str = option("astronaut", "bundled scikit-image picture", choices=IMAGES)
    layers: int = option(4, "retina layers; field size halves per layer", min=1)
    fields: int = option(32, "receptive fields per layer side", min=2)
    field_px: float = option(4.0, "width of a field in the largest layer, px (> 0)", min=0.01)
    top: float = option(0.01, "fraction of the brightest blurred pixels that are active", min=1e-4, max=0.5)
    reposition_px: float = option(48.0, "the target blob is put up to this many px from the centre", min=0.0)
    max_saccade_px: float = option(64.0, "largest saccade per axis, px", min=1.0)
    max_active: int = option(500, "redraw a reposition with more active pixels than this in view", min=1)
    min_blob_px: int = option(4, "blobs smaller than this many pixels are not chosen as targets", min=1)


class NaturalRetinaWorld(World):
    """The ch. 4 foveated retina over the salient pixels of a natural picture; saccades in px."""

    kind = "retina-natural"
    max_episode_steps = 1
    Params = NaturalRetinaParams

    def __init__(
        self,
        world_id: str = "retina-natural",
        seed: int = 0,
        params: NaturalRetinaParams | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(NaturalRetinaParams, overrides, name=self.kind, base=params)
        self.act_map = salient(load_image(prm.image), prm.top)
        self._cum = np.pad(self.act_map, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
        lab, n = ndimage.label(self.act_map > 0)
        sizes = ndimage.sum_labels(np.ones_like(lab), lab, index=np.arange(1, n + 1))
        cents = np.array(ndimage.center_of_mass(self.act_map, lab, np.arange(1, n + 1)))  # (row, col)
        keep = sizes >= prm.min_blob_px
        self.blobs = cents[keep][:, ::-1]  # (x, y) image px
        if len(self.blobs) == 0:
            raise ValueError(f"retina-natural: no blob of >= {prm.min_blob_px} px in {prm.image!r}")
        self.layout = field_layout(prm.layers, prm.fields, prm.field_px)
        self.n = self.layout.shape[0]
        self.order = np.random.default_rng(20_000 + seed).permutation(self.n)
        self.centres = self.layout[self.order, :2]
        self.sizes = self.layout[self.order, 2]
        self.eye = np.zeros(2)  # retina centre, image (x, y)
        self.target = self.blobs[0]

    def render(self) -> np.ndarray:
        """Activation of every field (published order): mean activity under it."""
        H, W = self.act_map.shape
        x = self.eye[0] + self.centres[:, 0]
        y = self.eye[1] - self.centres[:, 1]
        h = np.maximum(self.sizes / 2, 0.5)
        x0 = np.clip(np.round(x - h), 0, W).astype(int)
        x1 = np.clip(np.round(x + h), 0, W).astype(int)
        y0 = np.clip(np.round(y - h), 0, H).astype(int)
        y1 = np.clip(np.round(y + h), 0, H).astype(int)
        c = self._cum
        area = (x1 - x0) * (y1 - y0)
        s = c[y1, x1] - c[y0, x1] - c[y1, x0] + c[y0, x0]
        return np.where(area > 0, s / np.maximum(area, 1), 0.0).astype(np.float32)

    def target_offset_px(self) -> np.ndarray:
        """Where the target blob is seen, px from the retina centre (u right, v up)."""
        d = self.target - self.eye
        return np.array([d[0], -d[1]])

    def nearest_blob_px(self) -> float:
        """Distance from the retina centre to the nearest salient blob's centre, px."""
        return float(np.linalg.norm(self.blobs - self.eye, axis=1).min())

    def active_in_view(self) -> int:
        """Active pixels inside the 128-px retina."""
        H, W = self.act_map.shape
        r = self.params.fields * self.params.field_px / 2
        x0, x1 = int(np.clip(self.eye[0] - r, 0, W)), int(np.clip(self.eye[0] + r, 0, W))
        y0, y1 = int(np.clip(self.eye[1] - r, 0, H)), int(np.clip(self.eye[1] + r, 0, H))
        c = self._cum
        return int(c[y1, x1] - c[y0, x1] - c[y1, x0] + c[y0, x0])

    def spec(self) -> WorldSpec:
        """One float32 sensor ``fields`` (shuffled order), a 2-D saccade box in px."""
        m = self.params.max_saccade_px
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(SensorSpec("fields", "float32", (self.n,), 0.0, 1.0, "receptive-field activations, shuffled"),),
            action_space=ActionSpace(low=(-m, -m), high=(m, m), names=("u_px", "v_px")),
            reward_min=0.0,
            reward_max=float(self.n),
            program="retina",
            n_starts=0,
            params={"image": self.params.image, "layers": str(self.params.layers), "fields": str(self.params.fields)},
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Put the eye within `reposition_px` of a random blob (redrawn while the view is too busy)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        r = self.params.reposition_px
        for _ in range(100):
            self.target = self.blobs[self.rng.integers(len(self.blobs))]
            self.eye = self.target + self.rng.uniform(-r, r, 2)
            if self.active_in_view() <= self.params.max_active:
                break
        return StepResult({"fields": self.render()}, 0.0, False)

    def step(self, action: np.ndarray) -> StepResult:
        """One saccade (u, v) px, clipped; reward = total activation after it; always done."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.isfinite(a).all():
            raise ValueError(f"a saccade is 2 finite numbers (u, v), got {a.tolist()}")
        m = self.params.max_saccade_px
        a = np.clip(a, -m, m)
        self.eye = self.eye + np.array([a[0], -a[1]])
        f = self.render()
        return StepResult({"fields": f}, float(f.sum(dtype=np.float64)), True)

    def frame(self) -> np.ndarray:
        """The salient map under the retina, 8-bit."""
        r = int(self.params.fields * self.params.field_px / 2)
        x, y = int(round(self.eye[0])), int(round(self.eye[1]))
        out = np.zeros((2 * r, 2 * r), dtype=np.uint8)
        H, W = self.act_map.shape
        r0, r1, c0, c1 = max(y - r, 0), min(y + r, H), max(x - r, 0), min(x + r, W)
        if r0 < r1 and c0 < c1:
            out[r0 - y + r : r1 - y + r, c0 - x + r : c1 - x + r] = self.act_map[r0:r1, c0:c1] * 255
        return out

    def truth(self) -> Truth:
        """Each field's position in action units: minus the saccade (its centre, px) that centres it."""
        return Truth(self.world_id, "fields", {"positions": -self.centres.copy(), "pixels": self.centres.copy()})
