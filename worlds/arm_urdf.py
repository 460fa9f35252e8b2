"""URDF files for the arm world: found in `pybullet_data` or on disk, and rewritten with some links
scaled (the `morph` body change: the arm reloaded with longer or shorter links)."""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pybullet_data

from sensorimotor.protocol.params import ParamError


def resolve_urdf(path: str) -> str:
    """`path` as a file: itself if it exists, else inside `pybullet_data`; a ParamError otherwise."""
    for cand in (os.path.expanduser(path), os.path.join(pybullet_data.getDataPath(), path)):
        if os.path.isfile(cand):
            return os.path.abspath(cand)
    raise ParamError(f"arm: urdf {path!r} is neither a file nor in pybullet_data ({pybullet_data.getDataPath()})")


def _rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    r, pch, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(pch), math.sin(pch), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _vec(text: str | None, default: float = 0.0) -> np.ndarray:
    return np.array([float(v) for v in text.split()]) if text else np.full(3, default)


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.9g}" for x in v)


def scalable_links(root: ET.Element) -> list[str]:
    """Links whose length `morph` can scale: those with a child joint at a non-zero offset."""
    out = []
    for j in root.iter("joint"):
        o = j.find("origin")
        parent = j.find("parent")
        if parent is not None and o is not None and np.linalg.norm(_vec(o.get("xyz"))) > 1e-9:
            name = parent.get("link", "")
            if name not in out:
                out.append(name)
    return out


def morph_urdf(text: str, base_dir: str, scales: dict[str, float]) -> str:
    """The URDF `text` with each link of `scales` lengthened by its factor: its child joints'
    origins scaled, and its visual and collision shapes stretched along the direction of its first
    child joint; relative mesh paths (also ``package://``) made absolute against `base_dir`."""
    root = ET.fromstring(text)
    for mesh in root.iter("mesh"):
        f = mesh.get("filename", "")
        rel = f[len("package://") :] if f.startswith("package://") else f
        if not os.path.isabs(rel) and "://" not in rel:
            mesh.set("filename", os.path.join(base_dir, rel))
    links = {lk.get("name"): lk for lk in root.iter("link")}
    for name, s in scales.items():
        offsets = []
        for j in root.iter("joint"):
            parent = j.find("parent")
            o = j.find("origin")
            if parent is None or parent.get("link") != name or o is None:
                continue
            xyz = _vec(o.get("xyz"))
            if np.linalg.norm(xyz) > 1e-9:
                offsets.append(xyz)
                o.set("xyz", _fmt(xyz * s))
        if not offsets:
            raise ValueError(f"link {name!r} has no child joint at an offset")
        u = offsets[0] / np.linalg.norm(offsets[0])
        for part in links[name].findall("visual") + links[name].findall("collision"):
            o = part.find("origin")
            if o is None:
                o = ET.SubElement(part, "origin")
            xyz, rot = _vec(o.get("xyz")), _rpy_matrix(_vec(o.get("rpy")))
            o.set("xyz", _fmt(xyz + (s - 1.0) * float(xyz @ u) * u))
            local = np.abs(rot.T @ u)  # the stretch direction in the shape's own frame
            stretch = 1.0 + (s - 1.0) * local
            g = part.find("geometry")
            shape = g[0] if g is not None and len(g) else None
            if shape is None:
                continue
            if shape.tag == "mesh":
                shape.set("scale", _fmt(_vec(shape.get("scale"), 1.0) * stretch))
            elif shape.tag == "box":
                shape.set("size", _fmt(_vec(shape.get("size")) * stretch))
            elif shape.tag == "cylinder" and local[2] > 0.9:
                shape.set("length", f"{float(shape.get('length', '0')) * s:.9g}")
    return ET.tostring(root, encoding="unicode")
