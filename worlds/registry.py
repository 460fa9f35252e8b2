"""World kinds by name, so that `sme world NAME` and the demo can build them."""

from __future__ import annotations

from typing import Any, Callable, Mapping

from sensorimotor.worlds.base import World


def _gridworld(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.gridworld import GridWorld

    return GridWorld.from_params(world_id, seed, params)


def _gridworld_barrier(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    return _gridworld(world_id, seed, {**params, "barrier": "true"})


def _retina(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.retina import RetinaWorld

    return RetinaWorld.from_params(world_id, seed, params)


def _vergence(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.vergence import VergenceWorld

    return VergenceWorld.from_params(world_id, seed, params)


def _mountaincar(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.mountaincar import MountainCarWorld

    return MountainCarWorld.from_params(world_id, seed, params)


def _stereo(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.stereo_pair import StereoPairWorld

    return StereoPairWorld.from_params(world_id, seed, params)


def _bench(world_id: str, seed: int, params: Mapping[str, Any]) -> World:
    from sensorimotor.worlds.bench import BenchWorld

    return BenchWorld.from_params(world_id, seed, params)


WORLDS: dict[str, Callable[[str, int, Mapping[str, Any]], World]] = {
    "gridworld": _gridworld,
    "gridworld-barrier": _gridworld_barrier,
    "retina": _retina,
    "vergence": _vergence,
    "stereo": _stereo,
    "mountaincar": _mountaincar,
    "bench": _bench,
}


def make_world(name: str, world_id: str | None = None, seed: int = 0,
               params: Mapping[str, Any] | None = None) -> World:
    try:
        factory = WORLDS[name]
    except KeyError:
        raise ValueError(f"unknown world {name!r}; known: {', '.join(sorted(WORLDS))}") from None
    return factory(world_id or name, seed, dict(params or {}))
