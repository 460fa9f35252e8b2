"""`sme bench changes`'s command line: the scorecard (`changes`) or a life of changes in a row
(`changes_life`)."""

from __future__ import annotations

import argparse

from sensorimotor.tools.bench import changes, changes_life
from sensorimotor.tools.common import UsageError


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "changes",
        help="body changes on the zoo worlds: detection delay, misses, false alarms, relearning, beside river",
        description=changes.__doc__,
    )
    p.add_argument("--seeds", type=int, default=3, help="seeds per world and change: 0 .. N-1 (default 3)")
    p.add_argument("--quick", action="store_true", help="shorter budgets (a smoke test, not the figures)")
    p.add_argument(
        "--world",
        action="append",
        metavar="NAME",
        help=f"zoo worlds or the project's own (a whole label, or part of labels: Gridworld, 2 joints, Roving eye, "
        f"Retina, Mountain car; default: {'; '.join(changes.DEFAULT_WORLDS)})",
    )
    p.add_argument(
        "--change",
        action="append",
        metavar="KIND",
        help=f"only these changes (label or kind; default every one: {', '.join(c.label for c in changes.CHANGES)})",
    )
    p.add_argument("--no-quiet", action="store_true", help="skip the unperturbed run per world and seed")
    p.add_argument("--json", action="store_true", help="one JSON object per run, then per world and change")
    p.add_argument("--workers", type=int, default=1, help="processes the runs are spread over (default 1)")
    p.add_argument(
        "--life",
        type=int,
        default=0,
        metavar="N",
        help="instead: a life of N changes in a row per world (kinds drawn by seed, each followed by restore)",
    )
    p.set_defaults(func=_main_args)


def _main_args(a: argparse.Namespace) -> int:
    if a.seeds < 1 or a.workers < 1 or a.life < 0:
        raise UsageError("--seeds and --workers must be >= 1, --life >= 0")
    if a.life:
        return changes_life.main(a.life, a.world, a.seeds, a.json, a.quick)
    return changes.main(a.seeds, a.quick, a.world, a.change, a.json, a.workers, not a.no_quiet)
