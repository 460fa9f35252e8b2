"""Programs by name (the world's `program` hint picks one)."""

from __future__ import annotations

from typing import Any, Callable

from sensorimotor.agent.programs.base import EchoProgram, Program
from sensorimotor.protocol.messages import WorldSpec


def _gridworld(spec: WorldSpec, seed: int, **kw: Any) -> Program:
    from sensorimotor.agent.programs.gridworld import GridworldProgram

    return GridworldProgram(spec, seed, **kw)


def _retina(spec: WorldSpec, seed: int, **kw: Any) -> Program:
    from sensorimotor.agent.programs.retina import RetinaProgram

    return RetinaProgram(spec, seed, **kw)


def _vergence(spec: WorldSpec, seed: int, **kw: Any) -> Program:
    from sensorimotor.agent.programs.vergence import VergenceProgram

    return VergenceProgram(spec, seed, **kw)


def _mountaincar(spec: WorldSpec, seed: int, **kw: Any) -> Program:
    from sensorimotor.agent.programs.mountaincar import MountainCarProgram

    return MountainCarProgram(spec, seed, **kw)


PROGRAMS: dict[str, Callable[..., Program]] = {
    "vergence": _vergence,
    "gridworld": _gridworld,
    "retina": _retina,
    "mountaincar": _mountaincar,
    "echo": lambda spec, seed, **kw: EchoProgram(spec, seed),
}


def make_program(spec: WorldSpec, seed: int = 0, **kw: Any) -> Program:
    name = spec.program or spec.kind
    try:
        factory = PROGRAMS[name]
    except KeyError:
        raise ValueError(f"no developmental program {name!r} for world {spec.world_id!r}; "
                         f"known: {', '.join(sorted(PROGRAMS))}") from None
    program = factory(spec, seed, **kw)
    program.params = dict(kw)  # what a checkpoint rebuilds it from
    return program
