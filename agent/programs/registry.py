"""Programs by name (the world's `program` hint picks one), each with its declared parameters.

Program modules are imported lazily; `check_program_params` validates `PROGRAM.KEY=V` settings
before anything runs, so a daemon never meets an unknown key when a world attaches."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sensorimotor.agent.programs.base import Program
from sensorimotor.protocol.messages import WorldSpec
from sensorimotor.protocol.params import ParamError, cast_values, unknown_name


@dataclass(frozen=True)
class ProgramKind:
    """Where a program lives: module, Program class and its parameter dataclass (by name)."""

    module: str
    cls: str
    params: str
    summary: str

    def program_class(self) -> type[Program]:
        """The Program class (imports its module)."""
        return getattr(importlib.import_module(f"sensorimotor.agent.programs.{self.module}"), self.cls)

    def params_type(self) -> type:
        """The program's parameter dataclass (imports its module)."""
        return getattr(importlib.import_module(f"sensorimotor.agent.programs.{self.module}"), self.params)


PROGRAMS: dict[str, ProgramKind] = {
    "vergence": ProgramKind(
        "vergence", "VergenceProgram", "VergenceProgramParams", "LSPI vergence, trace lengths embedded as depth (ch. 7)"
    ),
    "gridworld": ProgramKind(
        "gridworld",
        "GridworldProgram",
        "GridworldProgramParams",
        "LSPI toward the goal, edit-distance embedding of greedy traces (ch. 5)",
    ),
    "retina": ProgramKind(
        "retina",
        "RetinaProgram",
        "RetinaProgramParams",
        "saccade learning, ballistic embedding of field positions (ch. 4)",
    ),
    "rovingeye": ProgramKind(
        "rovingeye",
        "RovingEyeProgram",
        "RovingEyeProgramParams",
        "ballistic jumps to the perceptual goal, start states embedded (ch. 5.2)",
    ),
    "mountaincar": ProgramKind(
        "mountaincar",
        "MountainCarProgram",
        "MountainCarProgramParams",
        "vergence geometry, then Sarsa(lambda) driving on top of it (ch. 8)",
    ),
    "generic": ProgramKind(
        "generic",
        "GenericProgram",
        "GenericProgramParams",
        "any world: PCA + RBF features (or state ids), LSPI, traces from start states (ch. 6)",
    ),
    "echo": ProgramKind("base", "EchoProgram", "EchoParams", "answers every observation with action 0 (benchmarks)"),
}


def program_kind(name: str) -> ProgramKind:
    """The registry entry of program `name`; a ParamError naming the known programs otherwise."""
    try:
        return PROGRAMS[name]
    except KeyError:
        raise ParamError(unknown_name("program", name, sorted(PROGRAMS))) from None


def program_params(name: str) -> type:
    """The parameter dataclass of program `name`."""
    return program_kind(name).params_type()


def check_program_params(params: Mapping[str, Mapping[str, Any]] | None) -> dict[str, dict[str, Any]]:
    """Validate `{program: {key: value}}` (strings or typed values) and return the typed overrides.

    Only the given keys are kept (JSON-friendly, so a daemon can record them in its config); every
    problem across all programs is reported in one ParamError.
    """
    out: dict[str, dict[str, Any]] = {}
    problems: list[str] = []
    for name, values in (params or {}).items():
        try:
            out[name] = cast_values(program_params(name), values, name)
        except ParamError as e:
            problems.append(str(e))
    if problems:
        raise ParamError("; ".join(problems))
    return out


FALLBACK = "generic"


def resolve_program(spec: WorldSpec) -> str:
    """The program that runs a world: its `program` hint (else its kind) when the agent has that
    program, else the generic program, which learns any world."""
    name = spec.program or spec.kind
    return name if name in PROGRAMS else FALLBACK


def make_program(spec: WorldSpec, seed: int = 0, **kw: Any) -> Program:
    """The program for a world spec (see `resolve_program`), built with its seed and hyperparameters.

    Parameters
    ----------
    spec : WorldSpec
        The world; its `program` hint (else its `kind`) names the program in `PROGRAMS`; a name
        the agent does not have gets the generic program.
    seed : int, default 0
        Seed of the program's random generator (programs are deterministic given it).
    **kw
        Hyperparameters of that program (strings or typed values), validated against its
        `Params` dataclass.

    Returns
    -------
    Program
        A fresh program.

    Raises
    ------
    ValueError
        `ParamError` for an unknown or invalid parameter;
        `SpecMismatch` if the world's sensors or actions do not suit the program.

    Examples
    --------
    ::

        program = make_program(spec, seed=0, samples_per_iteration="300")
        decision = program.act(observation)
    """
    return PROGRAMS[resolve_program(spec)].program_class()(spec, seed, **kw)
