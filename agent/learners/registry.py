"""Table learners by name (`generic.learner=NAME`): the ones in this package, and any that an
installed package declares in the ``sensorimotor.learners`` entry-point group::

    [project.entry-points."sensorimotor.learners"]
    my-learner = "my_package.my_module:MyLearner"

A learner is a class implementing `agent.learners.base.TableLearner`, built as
``Cls(n_states, n_actions, seed=SEED)``."""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from sensorimotor.agent.learners.base import TableLearner

#: the entry-point group through which installed packages offer table learners by name
ENTRY_POINT_GROUP = "sensorimotor.learners"

#: the table learners of this package: name -> "module:Class"
TABLE_LEARNERS = {"model": "sensorimotor.agent.learners.tabular_model:TabularModel"}

#: the learners of this package over a continuous state vector, driven by the generic program itself
#: (`generic.learner=NAME`): name -> "module:Class"
STATE_LEARNERS = {"reach": "sensorimotor.agent.learners.reach:ReachLearner"}


def outside_learners() -> list[str]:
    """The names installed packages declare in the entry-point group."""
    return sorted(ep.name for ep in entry_points(group=ENTRY_POINT_GROUP))


def table_learner_class(name: str) -> type[TableLearner] | None:
    """The class of table learner `name` (this package's, or an installed package's by entry
    point); None when no table learner has that name. A ValueError when the named class cannot be
    imported or does not implement the interface."""
    target = TABLE_LEARNERS.get(name)
    if target is None:
        found = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
        if not found:
            return None
        target = found[0].value
    module, _, cls = target.partition(":")
    try:
        klass = getattr(importlib.import_module(module), cls, None)
    except ImportError as e:
        raise ValueError(f"learner {name!r}: cannot import {module!r}: {e}") from None
    missing = [
        m
        for m in ("act", "learn_one", "job_args", "install", "complete", "set_stochastic", "reset", "state", "restore")
        if not callable(getattr(klass, m, None))
    ]
    if not isinstance(klass, type) or missing or not callable(getattr(klass, "plan_job", None)):
        what = f"lacks {', '.join(missing) or 'plan_job'}" if isinstance(klass, type) else "is not a class"
        raise ValueError(f"learner {name!r}: {target} {what} (see agent.learners.base.TableLearner)")
    return klass


__all__ = ["ENTRY_POINT_GROUP", "STATE_LEARNERS", "TABLE_LEARNERS", "outside_learners", "table_learner_class"]
