"""How a served world says which body changes it takes: ``WorldSpec.params["perturbations"]``, a
JSON object (see protocol/README.md) that `sme perturb --list --world ID` prints and `sme perturb`
checks a kind against before sending it. A world that does not advertise is checked against the
declaration of its kind, when this installation knows it."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

from sensorimotor.protocol.messages import WorldSpec
from sensorimotor.protocol.params import describe
from sensorimotor.worlds.body_changes.hook import FreeParams

KEY = "perturbations"


def advertisement(own: Mapping[str, type], generic: Mapping[str, type]) -> str:
    """The JSON text: kind -> {"from": "world" | "generic", "doc", "params": [[name, type, default,
    doc], ...] or null (parameters the world reads itself, as strings)}; the world's own first."""
    out: dict[str, Any] = {}
    for origin, kinds in (("world", own), ("generic", generic)):
        for kind, cls in kinds.items():
            free = issubclass(cls, FreeParams)
            out[kind] = {
                "from": origin,
                "doc": " ".join((cls.__doc__ or "").split()),
                "params": None if free else [[p.name, p.type, p.default, p.doc] for p in describe(cls)],
            }
    return json.dumps(out, separators=(",", ":"))


def advertised(spec: WorldSpec) -> dict[str, dict[str, Any]] | None:
    """The kinds a running world advertises (None: it does not, or not readably)."""
    raw = spec.params.get(KEY)
    if raw is None:
        return None
    try:
        data = json.loads(raw)
    except ValueError:
        return None
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        return None
    return data


def listing(world_id: str, world_kind: str, kinds: Mapping[str, Mapping[str, Any]]) -> str:
    """`sme perturb --list --world ID`: each kind with where it comes from and its parameters."""
    if not kinds:
        return f"world {world_id} ({world_kind}): no perturbations"
    lines = [f"world {world_id} ({world_kind}): {len(kinds)} perturbation kinds"]
    for kind, info in kinds.items():
        origin = "its own" if info.get("from") == "world" else "generic"
        lines.append(f"  {kind} ({origin}): {info.get('doc', '')}")
        params = info.get("params")
        if params is None:
            lines.append("    parameters: any k=v, read by the world itself")
        elif not params:
            lines.append("    (no parameters)")
        else:
            w = max(len(str(p[0])) for p in params)
            for name, tp, default, doc in params:
                lines.append(f"    {str(name).ljust(w)}  {tp} = {default}  {doc}")
    return "\n".join(lines)
