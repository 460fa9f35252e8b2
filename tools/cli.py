"""The `sme` command.

Everything every subcommand shares lives here: the -v/-q flags, the exit-status epilog, one logging
set-up, and the mapping of failures to exit statuses (see `tools.common.EXIT_CODES_EPILOG`).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterator

from sensorimotor.tools.bench import cli as bench_cli
from sensorimotor.tools.commands import agent as agent_cmd
from sensorimotor.tools.commands import (
    demo,
    perturb,
    record,
    replay,
    reproduce,
    secure,
    status,
    view,
    watch,
)
from sensorimotor.tools.commands import world as world_cmd
from sensorimotor.tools.common import (
    EXIT_CODES_EPILOG,
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    HelpFormatter,
    MissingExtra,
    UsageError,
    add_verbosity,
    setup_logging,
    verbosity,
)


def _subparsers(parser: argparse.ArgumentParser) -> Iterator[argparse.ArgumentParser]:
    """Every parser below `parser` (subcommands, and theirs), each once."""
    seen: set[int] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                if id(child) not in seen:
                    seen.add(id(child))
                    yield child
                    yield from _subparsers(child)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="sme",
        description="sensorimotor-embedding: an agent that learns the geometry of its body and sensors from "
        "raw experience, over Eclipse Zenoh. Start with `sme demo`.",
        epilog=EXIT_CODES_EPILOG,
        formatter_class=HelpFormatter,
    )
    add_verbosity(p)
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    for mod in (agent_cmd, world_cmd, perturb, watch, status, record, replay, view, demo, reproduce, bench_cli, secure):
        mod.add_parser(sub)
    replay.add_recover_parser(sub)
    for child in _subparsers(p):
        add_verbosity(child)
        child.formatter_class = HelpFormatter  # one layout for every help page
        child.epilog = f"{child.epilog}\n\n{EXIT_CODES_EPILOG}" if child.epilog else EXIT_CODES_EPILOG
    return p


def _command_name(args: argparse.Namespace) -> str:
    return " ".join(x for x in ("sme", getattr(args, "command", None), getattr(args, "bench", None)) if x)


def _stdout_to_devnull() -> None:
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush does not fail again
    (the recipe in the Python docs, "Note on SIGPIPE")."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout already closed or replaced
        pass
    finally:
        os.close(devnull)


def main(argv: list[str] | None = None) -> int:
    """Parse, set up logging once, run the command, and turn failures into exit statuses."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USAGE
    setup_logging(verbosity(args))
    name = _command_name(args)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _stdout_to_devnull()
        return EXIT_FAILURE
    except UsageError as e:
        print(f"{name}: {e}", file=sys.stderr)
        return EXIT_USAGE
    except MissingExtra as e:
        print(f"{name}: {e}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
