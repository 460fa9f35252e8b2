"""The hook by which an environment offers body changes of its own, with no change to this project.

An environment (the unwrapped one or any wrapper layer; `EmbeddableEnv` takes them as arguments)
defines ``sme_perturb(kind, params) -> str``, which changes its body and returns one line saying
what changed, and ``sme_perturbations``, a mapping of each kind it offers to either a parameter
dataclass (frozen, fields made with `protocol.params.option`: the values are parsed and checked
before the hook is called, and it receives the dataclass instance) or a one-line description (it
receives the parameters as a dict of strings and checks them itself). Its kinds are listed like
the built-in ones and take precedence over generic kinds of the same name. A hook that raises
(ValueError, KeyError...) refuses the change with its message.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from sensorimotor.protocol.messages import Control
from sensorimotor.protocol.params import quote
from sensorimotor.worlds.base import PerturbationError, check_perturbation

HOOK = "sme_perturb"
DECLARED = "sme_perturbations"


@dataclasses.dataclass(frozen=True)
class FreeParams:
    """A kind declared by a description only: its parameters go to the hook as strings."""


def free_kind(kind: str, doc: str) -> type:
    """A parameter type for a kind declared by description `doc`."""
    return type(f"{kind}_params", (FreeParams,), {"__doc__": doc})


def declared(decl: Any) -> dict[str, type]:
    """An environment's ``sme_perturbations`` as kind -> parameter type (descriptions become
    `FreeParams` subclasses); a ValueError for anything else."""
    if decl is None:
        return {}
    if callable(decl) and not isinstance(decl, Mapping):
        decl = decl()
    if not isinstance(decl, Mapping):
        raise ValueError(
            f"{DECLARED} must map each kind to a parameter dataclass or a description, not {type(decl).__name__}"
        )
    out: dict[str, type] = {}
    for kind, v in decl.items():
        if isinstance(v, type) and dataclasses.is_dataclass(v):
            out[str(kind)] = v
        elif isinstance(v, str):
            out[str(kind)] = free_kind(str(kind), v)
        else:
            raise ValueError(f"{DECLARED}[{kind!r}] must be a parameter dataclass or a description string")
    return out


def apply(hook: Callable[[str, Any], Any] | None, kinds: Mapping[str, type], world_kind: str, control: Control) -> str:
    """Call `hook` for `control` after checking its kind (and, for a declared dataclass, its
    parameters); a PerturbationError naming the valid kinds, or carrying the hook's own words."""
    cls = kinds.get(control.kind)
    if hook is None or cls is None:
        check_perturbation(world_kind, kinds, control)  # raises, naming the valid kinds
        raise PerturbationError(f"{world_kind} has no perturbation {quote(control.kind)}")
    params: Any = dict(control.params)
    if not issubclass(cls, FreeParams):
        params = check_perturbation(world_kind, kinds, control)
    try:
        what = hook(control.kind, params)
    except PerturbationError:
        raise
    except Exception as e:  # noqa: BLE001 - the user's code refused (or failed): the world stays up
        raise PerturbationError(f"{world_kind} {control.kind}: {type(e).__name__}: {e}") from None
    return str(what) if what is not None else f"{control.kind} applied"
