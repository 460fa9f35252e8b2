"""The changes and budgets of `sme bench changes` (tools/bench/changes.py), apart so that the
families of the project's own worlds (changes_families) can name them without importing the bench."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Change:
    """One change of the scorecard: a label, the Control kind and its parameters (kind None: no
    change, an unperturbed run that counts false alarms)."""

    label: str
    kind: str | None
    params: dict[str, str] = field(default_factory=dict)


#: Every generic kind with its default parameters (restore undoes one: it is the life's business)
CHANGES: tuple[Change, ...] = (
    Change("reverse", "reverse"),
    Change("permute", "permute"),
    Change("gain x2", "gain"),
    Change("lesion action 0", "lesion"),
    Change("lesion sensor (first half)", "lesion", {"what": "sensor"}),
    Change("noise sd 0.05", "noise"),
    Change("delay 1", "delay"),
)
NONE = Change("none (unperturbed)", None)


@dataclass(frozen=True)
class Budget:
    """Steps: the least before a change, the most to wait for the policy to be watched, the most
    after the change, and the unperturbed run's length."""

    before: int = 5_000
    ready_by: int = 60_000
    after: int = 40_000
    quiet: int = 100_000


QUICK = Budget(2_000, 20_000, 15_000, 20_000)
FULL = Budget()
