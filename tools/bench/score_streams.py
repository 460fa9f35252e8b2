"""Score a drop detector on recorded performance streams: `python -m
sensorimotor.tools.bench.score_streams FILE [--detector NAME] [--params JSON]`.

FILE holds one JSON object per line (gzip when it ends in .gz): `change` (a label; "none ..." for
an unperturbed stream), `seed`, `change_index` (the first sample after the change, null for none),
`resets` (samples where the agent's detector was reset) and `values`. The scorecard's mountain car
streams are kept in docs/results/bench-changes-mountaincar/streams.jsonl.gz (recorded by
`sme bench changes`' runs with the agent not reacting); the default detector is the one the car's
program asks for. Prints false alarms in the unperturbed streams and before each change, and each
change's delay in samples (the scorecard's `score`)."""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, make_detector
from sensorimotor.tools.bench.changes import score


@dataclass(frozen=True)
class StreamScores:
    """False alarms over all samples before a change (or in a whole unperturbed stream), the
    samples they were counted in, and each change's delay (None: missed)."""

    false_alarms: int
    samples: int
    delays: dict[str, list[int | None]]


def load(path: str) -> list[dict[str, Any]]:
    """The recorded streams of `path` (see the module's doc)."""
    opener = gzip.open if path.endswith(".gz") else open
    with opener(path, "rt") as f:
        return [json.loads(line) for line in f if line.strip()]


def score_streams(streams: list[dict[str, Any]], name: str, params: dict[str, Any]) -> StreamScores:
    """Every stream scored by a fresh detector `name` with `params` (remade where the agent's was reset)."""
    fa, samples = 0, 0
    delays: dict[str, list[int | None]] = {}
    for s in streams:
        at = s["change_index"]
        end = len(s["values"]) + 1 if at is None else at
        f, d = score(lambda: make_detector(name, **params), s["values"], s["resets"], end)
        fa, samples = fa + f, samples + min(end, len(s["values"]))
        if at is not None:
            delays.setdefault(s["change"], []).append(d)
    return StreamScores(fa, samples, delays)


def main(path: str, name: str = DEFAULT_DETECTOR, params: dict[str, Any] | None = None) -> int:
    if params is None:
        from sensorimotor.agent.programs.mountaincar import MountainCarProgram

        params = dict(MountainCarProgram.detector_params)
    r = score_streams(load(path), name, params)
    print(f"{name} {params}: {r.false_alarms} false alarms in {r.samples:,} samples before a change")
    for change, ds in r.delays.items():
        seen = [d for d in ds if d is not None]
        med = f"median {np.median(seen):g}" if seen else "none seen"
        print(f"  {change}: delays {ds} ({len(ds) - len(seen)} missed, {med})")
    return 0


def _cli(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensorimotor.tools.bench.score_streams", description=__doc__)
    p.add_argument("file", help="recorded streams, one JSON object per line (.gz: gzip)")
    p.add_argument("--detector", default=DEFAULT_DETECTOR, help=f"detector name (default {DEFAULT_DETECTOR})")
    p.add_argument("--params", default=None, help="its parameters as JSON (default: the mountain car program's)")
    a = p.parse_args(argv)
    return main(a.file, a.detector, None if a.params is None else json.loads(a.params))


if __name__ == "__main__":
    sys.exit(_cli())
