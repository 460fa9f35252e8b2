"""Which learner the generic program drives, from what the world observes and acts with
(`generic.learner=auto`: see `agent.programs.generic`), checked against the learners there are."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.learners.base import TableLearner
from sensorimotor.agent.learners.reach import fits as reach_fits
from sensorimotor.agent.learners.registry import outside_learners, table_learner_class
from sensorimotor.agent.programs.generic_params import LEARNERS, OWN_LEARNERS, GenericProgramParams
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import WorldSpec


@dataclass(frozen=True)
class LearnerChoice:
    """The learner picked and the facts of the observation it was picked by."""

    learner: str
    table_class: type[TableLearner] | None  # a table learner of the registry (None: one the program drives)
    ids: bool  # one integer sensor with few values: a state id
    symbols: bool  # integer sensors with few values each: tabulated by distinct observation
    values: int  # observed values in all (the sensors' elements)
    frames: bool  # a sensor of two or more axes (a camera)
    box: bool  # a box action of two or more values


def choose_learner(spec: WorldSpec, prm: GenericProgramParams) -> LearnerChoice:
    """The learner for `spec` (`prm.learner`, or by the observation when `auto`); SpecMismatch naming
    the valid choices for an unknown name or a table learner over an observation that is no table."""
    s0 = spec.sensors[0]
    ids = (
        len(spec.sensors) == 1
        and np.dtype(s0.dtype).kind in "iu"
        and int(np.prod(s0.shape)) == 1
        and 0 < s0.high - s0.low + 1 <= prm.max_categories
    )
    symbols = all(
        np.dtype(s.dtype).kind in "iub" and 0 <= s.high - s.low + 1 <= prm.symbol_values for s in spec.sensors
    )
    d = sum(int(np.prod(s.shape)) for s in spec.sensors)
    frames = any(len(s.shape) >= 2 for s in spec.sensors)  # a camera: its frames are planned over by motor map
    box = not spec.action_space.discrete and len(spec.action_space.low) >= 2
    learner = prm.learner
    if learner == "auto":
        learner = (
            "model"
            if ids or symbols
            else "reach"
            if reach_fits(spec)
            else "planner"
            if box and (d <= prm.planner_max_dims or frames)
            else "sarsa"
            if d <= prm.sarsa_max_dims
            else "lspi"
        )
    table_class = None if learner in OWN_LEARNERS else table_learner_class(learner)
    if learner not in OWN_LEARNERS and table_class is None:
        valid = ", ".join([*LEARNERS, *outside_learners()])
        raise SpecMismatch(f"generic program: no learner {learner!r}; valid: {valid}")
    if table_class is not None and not (ids or symbols):
        raise SpecMismatch(
            f"generic program: learner {learner!r} learns over a table of states; world {spec.world_id} "
            "observes neither a state id nor integer symbols (learner=auto picks one that fits)"
        )
    return LearnerChoice(learner, table_class, bool(ids), bool(symbols), d, frames, box)
