"""What the viewer draws, as plain arrays: models, registered curves, contact and normal.

A *scene* is a JSON-ready dict built from a recognition's result (the dict of
:meth:`tactrec.recognition.Recognition.to_json`, as ``tactrec recognize --json``
writes it), the touch's curves in the sensor's frame and the models.  Each of
the ranking's first ``shown`` registered models is one *view*: its surface
(a mesh decimated to at most ``faces`` triangles, or a closed-form surface
sampled on a grid of its domain), the curves mapped onto it by that model's
pose (``model = scale R data + t``, :class:`~tactrec.registration.result.Registration`),
drawn as tubes, the contact and the normal.  The first view is the best
model's; the page shows one view at a time.  The ranking's other models are
listed (``others``) with why they have no view: rejected, or left unrefined by
the search (``fast`` defers the models its cheap stage puts far behind the
best: their errors say nothing about them), or beyond the ``shown``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["touch_scene", "surface_mesh", "tube", "view", "placed", "pose_of", "others", "COLOURS"]

SIDES = 8            # a tube's cross-section: an octagon
TUBE = 0.006         # a tube's radius, of the view's size (its bounding box's diagonal)
#: a touch's curves, one colour each (a session's touches, one colour each)
COLOURS = ["#d62728", "#1f77b4", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]


def surface_mesh(model, *, faces: int) -> tuple[np.ndarray, np.ndarray, int]:
    """``(vertices (v, 3), triangles (f, 3), faces before decimation)`` to draw ``model``.

    A mesh with more than ``faces`` triangles is decimated by quadric error (trimesh's
    ``simplify_quadric_decimation``, the fast-simplification library); a closed-form surface is
    sampled on a grid of its domain with about ``faces`` triangles."""
    if getattr(model, "kind", None) == "mesh":
        vertices, triangles = np.asarray(model.vertices, float), np.asarray(model.faces, np.int64)
        original = len(triangles)
        if original > faces:
            import trimesh

            small = trimesh.Trimesh(vertices, triangles, process=False).simplify_quadric_decimation(face_count=faces)
            vertices, triangles = np.asarray(small.vertices, float), np.asarray(small.faces, np.int64)
        return vertices, triangles, original
    grid = max(10, int(np.sqrt(faces / 2.0)) + 1)
    # both ends of each parameter, so that a periodic one closes its seam
    uu, vv = np.meshgrid(np.linspace(model.domain_u.lo, model.domain_u.hi, grid),
                         np.linspace(model.domain_v.lo, model.domain_v.hi, grid), indexing="ij")
    vertices = np.asarray(model.evaluate(uu, vv), float).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(grid - 1), np.arange(grid - 1), indexing="ij")
    a = (i * grid + j).ravel()
    triangles = np.concatenate([np.stack([a, a + grid, a + 1], 1), np.stack([a + 1, a + grid, a + grid + 1], 1)])
    keep = np.all(np.isfinite(vertices[triangles]).reshape(len(triangles), -1), axis=1)
    return np.nan_to_num(vertices), triangles[keep], 2 * (grid - 1) ** 2


def tube(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """A tube of ``radius`` around the polyline ``points (n, 3)``: ``(vertices (n SIDES, 3),
    triangles (2 (n - 1) SIDES, 3))``, rings of ``SIDES`` vertices in planes across the curve."""
    points = np.asarray(points, float)
    n = len(points)
    tangent = np.gradient(points, axis=0) if n > 1 else np.array([[1.0, 0.0, 0.0]])
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-300)
    # one normal carried along the curve (no twist where the curve turns)
    normals = np.zeros_like(points)
    seed = np.eye(3)[int(np.argmin(np.abs(tangent[0])))]
    normals[0] = np.cross(tangent[0], seed)
    for k in range(1, n):
        v = normals[k - 1] - (normals[k - 1] @ tangent[k]) * tangent[k]
        normals[k] = v if np.linalg.norm(v) > 1e-12 else np.cross(tangent[k], seed)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    binormals = np.cross(tangent, normals)
    angle = 2.0 * np.pi * np.arange(SIDES) / SIDES
    ring = np.cos(angle)[None, :, None] * normals[:, None] + np.sin(angle)[None, :, None] * binormals[:, None]
    vertices = (points[:, None] + radius * ring).reshape(-1, 3)
    k, s = np.meshgrid(np.arange(n - 1), np.arange(SIDES), indexing="ij")
    a, b = k * SIDES + s, k * SIDES + (s + 1) % SIDES
    triangles = np.concatenate([np.stack([a, a + SIDES, b], -1).reshape(-1, 3),
                                np.stack([b, a + SIDES, b + SIDES], -1).reshape(-1, 3)])
    return vertices, triangles


def _rounded(x: np.ndarray, size: float) -> list:
    """``x`` to a ten-thousandth of ``size`` (finer than a screen's pixel, and a third of the text)."""
    digits = max(0, 4 - int(np.floor(np.log10(size))))
    return np.round(np.asarray(x, float), digits).tolist()


def pose_of(entry: dict) -> tuple[np.ndarray, np.ndarray, float]:
    """A ranking entry's pose ``(R (3, 3), t (3,), scale)``: ``model = scale R data + t``."""
    return (np.asarray(entry["rotation"], float), np.asarray(entry["translation"], float),
            float(entry.get("scale", 1.0)))


def placed(entry: dict, x: np.ndarray) -> np.ndarray:
    """Data points ``(..., 3)`` in the model's frame under ``entry``'s pose."""
    R, t, scale = pose_of(entry)
    return scale * np.asarray(x, float) @ R.T + t


def view(entry: dict, model, *, faces: int, curves: list, normal, marks=(), lines=(), towards=None,
         contact=None) -> dict:
    """One model's view: its surface (at most ``faces`` triangles) and, in its frame, ``curves``
    (``{"points": (n, 3), "colour", "name", "opacity"}``, drawn as tubes), the ``contact`` (``(3,)``;
    the entry's ``location`` where None) and ``normal`` (``(3,)``, drawn 8 % of the view's size long), ``marks``
    (``{"point": (3,), "name", "colour", "symbol"}``: ``circle``, ``x`` or ``diamond``) and ``lines``
    (``{"points": (n, 3), "name", "colour"}``, drawn as tubes half as thick as the curves'), all
    already in the model's frame.  The axes' ``range`` holds the surface
    and the curves drawn opaque, padded by 5 % of the view's size.  The camera looks at the contact along
    the normal, or at the surface point ``towards`` (``(3,)``) from the side away from the surface's
    centre where one is given, from no farther than the surface leaves clear (``clear``,
    :func:`_clear`)."""
    vertices, triangles, original = surface_mesh(model, faces=faces)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    size = float(np.linalg.norm(hi - lo)) or 1.0
    drawn = []
    for c in curves:
        drawn.append(dict(_tube(c["points"], TUBE * size, size), colour=c["colour"], name=c["name"],
                          opacity=c.get("opacity", 1.0)))
    normal = np.asarray(normal, float)
    contact = np.asarray(entry["location"] if contact is None else contact, float)
    arrow = 0.08 * size * normal / (np.linalg.norm(normal) or 1.0)
    # the axes' range: the surface and the curves that fit it (a slipped touch's may lie far off)
    kept = np.concatenate([vertices] + [np.asarray(c["points"], float) for c in curves if c.get("opacity", 1.0) >= 1.0])
    pad = 0.05 * size
    target = contact if towards is None else np.asarray(towards, float)
    look = normal if towards is None else target - 0.5 * (lo + hi)
    look = normal if not np.linalg.norm(look) > 0 else look
    look = look / np.linalg.norm(look)
    return {
        "model": entry["model"], "error": entry["error"], "probability": entry.get("probability"),
        "units": getattr(model, "units", None) or "",
        "surface": {"vertices": _rounded(vertices, size), "triangles": triangles.tolist(),
                    "faces": int(len(triangles)), "original_faces": int(original)},
        "curves": drawn,
        "contact": _rounded(contact, size),
        "normal": _rounded(arrow, size),
        "look": _rounded(look, 1.0),
        "target": _rounded(target, size),
        "clear": _clear(vertices, triangles, target, look, size),
        "normal_tube": _tube(np.stack([contact, contact + arrow]), 0.5 * TUBE * size, size),
        "marks": [dict(m, point=_rounded(m["point"], size)) for m in marks],
        "lines": [dict(_tube(ln["points"], 0.5 * TUBE * size, size), name=ln["name"], colour=ln["colour"])
                  for ln in lines],
        "size": size,
        "range": [_rounded(kept.min(axis=0) - pad, size), _rounded(kept.max(axis=0) + pad, size)],
    }


def _tube(points, radius: float, size: float) -> dict:
    v, f = tube(np.asarray(points, float), radius)
    return {"vertices": _rounded(v, size), "triangles": f.tolist()}


def _clear(vertices: np.ndarray, triangles: np.ndarray, target: np.ndarray, look: np.ndarray, size: float) -> float:
    """How far (as a share of ``size``) the line of sight from ``target`` along ``look`` runs before it
    meets the surface (10 where it meets nothing; hits within 2 % of ``size``, the decimated
    surface's own waviness about the target, do not count): the camera stays nearer, so that the
    inside of a cup or a handle's far side does not hide the touch."""
    origin = target + 1e-3 * size * look
    # Moller-Trumbore, the one ray against every triangle
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    e1, e2 = b - a, c - a
    p = np.cross(look, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12 * size * size
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ look) * inv
    distance = np.einsum("ij,ij->i", e2, q) * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (distance > 0.02 * size)
    far = distance[hit] if hit.any() else np.array([10.0 * size])
    return float(min(10.0, far.min() / size))


def others(result: dict, views: list) -> list:
    """The ranking's models without a view, and why."""
    drawn = {v["model"] for v in views}
    return [{"model": r["model"], "error": r.get("error"), "probability": r.get("probability"),
             "reason": r.get("rejected") or "registered, beyond the views shown"}
            for r in result.get("ranking", []) if r["model"] not in drawn]


def touch_scene(result: dict, curves: list[np.ndarray], models: dict, *, shown: int = 5,
                faces: int = 10000, runner_faces: int = 4000, title: str = "") -> dict:
    """The scene of one touch's recognition (see the module text).

    Parameters
    ----------
    result : dict
        The recognition's JSON result (``ranking`` with each registered model's ``rotation``,
        ``translation``, ``scale``, ``location``, ``error`` and ``probability``; ``normal``).
    curves : list of (n_i, 3) arrays
        The touch's curves, sensor frame.
    models : dict
        Name to model, for at least the models shown.
    shown : int
        How many registered models, best first, get a view.
    faces, runner_faces : int
        The best model's mesh is drawn with at most ``faces`` triangles, the others' with
        ``runner_faces`` (decimated where they have more).
    """
    registered = [r for r in result.get("ranking", []) if r.get("error") is not None][:shown]
    views = []
    for r in registered:
        R = pose_of(r)[0]
        drawn = [{"points": placed(r, c), "colour": COLOURS[n % len(COLOURS)], "name": f"curve {n + 1}"}
                 for n, c in enumerate(curves)]
        views.append(view(r, models[r["model"]], faces=faces if not views else runner_faces, curves=drawn,
                          normal=R @ np.asarray(result.get("normal", [0.0, 0.0, 1.0]), float)))
    return {"kind": "touch", "title": title, "best": result.get("best"), "confidence": result.get("confidence"),
            "unknown": result.get("unknown"), "views": views, "others": others(result, views), "legend": []}
