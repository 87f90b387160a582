"""Solids described as data and evaluated as signed distance fields: the parts of the generated catalogue.

A solid is a tree of plain dicts (JSON, never code): a primitive (``sphere``,
``ellipsoid``, ``box``, ``cylinder``, ``torus``, ``capsule``, ``halfspace``),
placed by a ``center`` and a row-major rotation ``rot`` that takes the
primitive's own frame to the world's, or a combination (``union``,
``smooth`` union of radius ``k``, ``subtract``, ``intersect``) of
``parts``.  :func:`distance` evaluates the tree at points: negative inside,
positive outside, zero on the surface.  The primitives' fields are Inigo
Quilez's; a combination's is a bound on the distance, which is all marching
cubes needs (:func:`tactrec.bench.catalogue.surface_mesh`).

Every product is written out element by element: a field is the same to the
last bit under every BLAS kernel, so the catalogue's meshes are too.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distance", "rotation", "PRIMITIVES", "COMBINATIONS"]

PRIMITIVES = ("sphere", "ellipsoid", "box", "cylinder", "torus", "capsule", "halfspace")
COMBINATIONS = ("union", "smooth", "subtract", "intersect")


def rotation(rng: np.random.Generator) -> list[float]:
    """A uniformly random rotation (row-major, nine numbers), from a unit quaternion."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]


def _local(node: dict, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The points ``p`` (n, 3) in the primitive's own frame: ``rot^T (p - center)``, element by element."""
    c = node.get("center", (0.0, 0.0, 0.0))
    r = node.get("rot", (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0))
    dx, dy, dz = p[:, 0] - c[0], p[:, 1] - c[1], p[:, 2] - c[2]
    return (r[0] * dx + r[3] * dy + r[6] * dz, r[1] * dx + r[4] * dy + r[7] * dz,
            r[2] * dx + r[5] * dy + r[8] * dz)


def _length(*parts: np.ndarray) -> np.ndarray:
    total = parts[0] * parts[0]
    for part in parts[1:]:
        total = total + part * part
    return np.sqrt(total)


def _primitive(node: dict, p: np.ndarray) -> np.ndarray:
    x, y, z = _local(node, p)
    op = node["op"]
    if op == "sphere":
        return _length(x, y, z) - node["radius"]
    if op == "ellipsoid":
        a, b, c = node["radii"]
        k0 = _length(x / a, y / b, z / c)
        k1 = _length(x / (a * a), y / (b * b), z / (c * c))
        return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)
    if op == "box":
        rounding = node.get("round", 0.0)
        qx, qy, qz = (np.abs(v) - (h - rounding) for v, h in zip((x, y, z), node["half"]))
        outside = _length(np.maximum(qx, 0.0), np.maximum(qy, 0.0), np.maximum(qz, 0.0))
        return outside + np.minimum(np.maximum(qx, np.maximum(qy, qz)), 0.0) - rounding
    if op == "cylinder":                      # about the local z axis, from -half to +half
        dr = _length(x, y) - node["radius"]
        dh = np.abs(z) - node["half"]
        return np.minimum(np.maximum(dr, dh), 0.0) + _length(np.maximum(dr, 0.0), np.maximum(dh, 0.0))
    if op == "torus":                         # in the local xy plane
        return _length(_length(x, y) - node["major"], z) - node["minor"]
    if op == "capsule":                       # along the local z axis, from -half to +half
        return _length(x, y, z - np.clip(z, -node["half"], node["half"])) - node["radius"]
    if op == "halfspace":                     # the points below the local xy plane
        return z
    raise ValueError(f"unknown solid {op!r}")


def distance(node: dict, p: np.ndarray) -> np.ndarray:
    """The signed distance (a bound on it for combinations) of the solid ``node`` at the points ``p`` (n, 3)."""
    op = node["op"]
    if op in PRIMITIVES:
        return _primitive(node, p)
    fields = [distance(part, p) for part in node["parts"]]
    out = fields[0]
    for field in fields[1:]:
        if op == "union":
            out = np.minimum(out, field)
        elif op == "intersect":
            out = np.maximum(out, field)
        elif op == "subtract":
            out = np.maximum(out, -field)
        elif op == "smooth":                  # a polynomial smooth minimum, blending over k
            k = node["k"]
            h = np.clip(0.5 + 0.5 * (field - out) / k, 0.0, 1.0)
            out = field + (out - field) * h - k * h * (1.0 - h)
        else:
            raise ValueError(f"unknown combination {op!r}")
    return out
