"""The `sme` command."""

from __future__ import annotations

import argparse
import sys

from sensorimotor.tools import agent_cmd, demo, perturb, record, replay, reproduce, status, view, watch, world_cmd
from sensorimotor.tools.bench import cli as bench_cli


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sme",
        description="sensorimotor-embedding: an agent that learns the geometry of its body and sensors from "
        "raw experience, over Eclipse Zenoh. Start with `sme demo`.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for mod in (agent_cmd, world_cmd, perturb, watch, status, record, replay, view, demo, reproduce, bench_cli):
        mod.add_parser(sub)
    replay.add_recover_parser(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
