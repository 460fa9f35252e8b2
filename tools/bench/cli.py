"""`sme bench`: the benchmarks."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help="benchmarks (loop, embedding, record, detectors, world, fuzz, gap, soak, scale, zoo, car, ros2, changes)",
        description="Run a benchmark; see its --help.",
    )
    bsub = p.add_subparsers(dest="bench", metavar="BENCH")
    from sensorimotor.tools.bench import (
        car,
        changes_cli,
        detectors,
        embedding,
        fuzz,
        gap,
        loop,
        record,
        ros2,
        scale,
        soak,
        world,
        zoo,
    )

    loop.add_parser(bsub)
    embedding.add_parser(bsub)
    record.add_parser(bsub)
    detectors.add_parser(bsub)
    world.add_parser(bsub)
    fuzz.add_parser(bsub)
    gap.add_parser(bsub)
    soak.add_parser(bsub)
    scale.add_parser(bsub)
    zoo.add_parser(bsub)
    car.add_parser(bsub)
    changes_cli.add_parser(bsub)
    ros2.add_parser(bsub)
    p.set_defaults(func=lambda a: p.print_help() or 2)
