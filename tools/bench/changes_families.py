"""The project's own worlds in `sme bench changes`: the gridworld, the arm, the roving eye, the
retina and the mountain car, each with the changes it takes (`sme perturb --list --world ID`: its
own kinds first, then the generic ones it has no own kind for), run by the scorecard's machinery
(`changes.run_one`).

A `Family` is a zoo entry with what the zoo's generic rows do not need: its own list of changes, its
budgets, the program it is learned by when its world's own program does not watch its reward (the
gridworld program of ch. 5 has no `performance`: the generic program learns the grid here, as
`program: generic`), for a world without start states (the retina) how many stream samples count
as one sweep, for a program that names only its first map after a drop and then refines it
periodically (retina, roving eye) that later versions count, and for a stream of scores rather
than goals (the mountain car's -(car steps) / 400 per training episode) what counts as a goal."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import WorldSpec
from sensorimotor.tools.bench.changes_kinds import CHANGES, QUICK, Budget, Change
from sensorimotor.tools.bench.zoo import ZooWorld
from sensorimotor.worlds.body_changes.layer import BodyChanges
from sensorimotor.worlds.registry import make_world


class _AsProgram(BodyChanges):
    """The generic body changes over `world`, its spec naming `program` (the program it is learned by)."""

    def __init__(self, world: Any, program: str) -> None:
        super().__init__(world)
        self._program = program

    def spec(self) -> WorldSpec:
        return dataclasses.replace(super().spec(), program=self._program)


@dataclass(frozen=True)
class Family(ZooWorld):
    """A world of the project's own in the scorecard (see the module's doc)."""

    changes: tuple[Change, ...] = ()
    budget: Budget = Budget()
    quick_budget: Budget = QUICK
    program_name: str = ""  # "" : the world's own program
    sweep: int = 0  # stream samples per sweep when the world has no start states (0: its n_starts)
    note: str = field(default="", compare=False)

    refines: bool = False  # its program names the drop in one version and then refines the map periodically
    goal_above: float | None = None  # a stream of scores: a value above this is a goal reached

    def harm(self, pre: list[float], post: list[float]) -> float | None:
        """1 - (the share of goals reached in the sweep after the change / in the sweep before):
        of the watched values themselves (a goal fraction already), or of those above `goal_above`."""
        if not pre or not post:
            return None
        a, b = (
            (float(np.mean(pre)), float(np.mean(post)))
            if self.goal_above is None
            else (float(np.mean(np.array(pre) > self.goal_above)), float(np.mean(np.array(post) > self.goal_above)))
        )
        return float(1.0 - b / a) if a > 0 else None

    def build(self, seed: int) -> BodyChanges:
        """The world of `seed` with the generic body changes (and the program it is learned by)."""
        w = make_world(self.world, None, seed, self.params)
        return _AsProgram(w, self.program_name) if self.program_name else BodyChanges(w)


def _generic(*labels: str) -> tuple[Change, ...]:
    by = {c.label: c for c in CHANGES}
    return tuple(by[lb] for lb in labels)


#: the arm's own kinds (docs/arm.md): the first moving joint, its defaults
ARM_OWN = (
    Change("reverse joint 1 (own)", "reverse"),
    Change("lesion: joint 1 locked (own)", "lesion"),
    Change("gain: joint 1 x1.5 (own)", "gain"),
    Change("morph: link x1.3 (own)", "morph"),
)
ARM_GENERIC = _generic("permute", "noise sd 0.05", "delay 1")

#: the retina's own kinds (ch. 4): up/down swapped, a lesion in the fovea, field noise
RETINA_OWN = (
    Change("reverse up/down (own)", "reverse"),
    Change("lesion fovea r 6 px (own)", "lesion"),
    Change("noise sd 0.05 (own)", "noise"),
)

FAMILIES: tuple[Family, ...] = (
    Family(
        "Gridworld 9x9 (generic program)",
        "gridworld",
        changes=CHANGES,
        budget=Budget(5_000, 40_000, 30_000, 100_000),
        quick_budget=Budget(2_000, 15_000, 10_000, 15_000),
        program_name="generic",
        note="the gridworld program (ch. 5) does not watch its reward; the generic program learns the grid here",
    ),
    Family(
        "Arm Kuka iiwa, 2 joints (sme world arm)",
        "arm",
        changes=ARM_OWN + ARM_GENERIC,
        budget=Budget(5_000, 30_000, 20_000, 34_000),
        quick_budget=Budget(2_000, 12_000, 8_000, 12_000),
    ),
    Family(
        "Roving eye",
        "rovingeye",
        changes=(Change("gain x1.5 (own)", "gain"), *_generic("reverse", "permute", "lesion action 0", "delay 1")),
        budget=Budget(25_000, 40_000, 40_000, 100_000),
        quick_budget=Budget(15_000, 25_000, 20_000, 12_000),
        refines=True,
    ),
    Family(
        "Retina",
        "retina",
        changes=RETINA_OWN + _generic("permute", "gain x2", "delay 1"),
        budget=Budget(6_000, 20_000, 6_000, 34_000),  # 3 seeds: 102,000 unperturbed saccades
        quick_budget=Budget(2_000, 10_000, 8_000, 12_000),
        sweep=100,
        refines=True,
    ),
    Family(
        "Mountain car (ch. 8)",
        "mountaincar",
        program={"eval_every": "1000000000"},
        changes=(
            Change("morph: baseline 1.0 -> 1.4 m (own)", "morph", {"baseline": "1.4"}),
            *_generic("reverse", "permute", "gain x2", "lesion action 0", "delay 1"),
        ),
        budget=Budget(0, 700_000, 150_000, 400_000),
        quick_budget=Budget(0, 300_000, 60_000, 20_000),
        sweep=20,
        goal_above=-1.0,
    ),
)


def family(label: str) -> Family | None:
    """The family of that exact label (case-insensitive), or None."""
    return next((f for f in FAMILIES if f.label.lower() == label.lower()), None)


__all__ = ["FAMILIES", "Family", "family"]
