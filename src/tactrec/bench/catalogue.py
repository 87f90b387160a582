"""A generated catalogue of meshes: families of solids and their near-duplicates, made on demand from a seed.

Large real catalogues hold many shapes and, among them, families of near
twins: the same part at another size, or with a hole drilled, a boss or a
handle added.  :func:`generate` makes ``count`` such meshes from ``seed``,
four to a family:

- ``a``: a body (a smooth blob of ellipsoids, a block, a stepped shaft, a
  thin plate, a ring, an open cup, a bent hook or a dumbbell) with one to
  three features (a through hole, a pocket, a boss, a knob, a thin fin, a
  handle), placed on the body's surface;
- ``b``: ``a`` at another size (20-50% larger, or smaller where larger would
  pass 250 mm);
- ``c``: ``a`` less its last feature;
- ``d``: ``a`` with one more feature.

So the catalogue has holes, handles, thin parts, sharp edges and smooth
blobs, 40-250 mm across (the largest side of the bounding box).  Each solid
is a tree of signed distance fields (:mod:`tactrec.bench.shapes`, data, never
code), meshed by libigl's marching cubes on a grid of :data:`GRID` cells
along its largest side (the field exact near the surface, :func:`_banded`), kept to its largest connected piece and decimated by
collapsing its shortest edges (libigl's ``decimate``, which keeps it closed) to :data:`FACES` triangles, the resolution of the YCB scans
that ship with tactrec.  Nothing in tactrec is tuned on these meshes.

The meshes are written as binary PLY files into a folder named by the
generator's version and the seed, one atomic write each, with
``catalogue.json`` (each model's family, variant, body, features and size):
a run that is stopped resumes where it stopped, and the same seed gives the
same files to the byte.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from .shapes import distance, rotation

__all__ = ["generate", "solid", "surface_mesh", "BODIES", "FEATURES", "VARIANTS", "GRID", "FACES", "SIZE_MM",
           "family_of"]

#: bump when what a seed makes changes: a new version is a new folder
VERSION = 1
#: marching-cubes cells along a solid's largest side (a fin or a cup's wall is three to four cells thick)
GRID = 128
#: the coarse grid's spacing in cells, and the band (cells) about the surface where the field is exact
STRIDE, BAND = 4, 7.0
#: the triangles each mesh is decimated to (the shipped YCB scans have 16,384)
FACES = 16_384
#: the span of the catalogue's sizes: the largest side of the bounding box, mm
SIZE_MM = (40.0, 250.0)
BODIES = ("blob", "block", "shaft", "plate", "ring", "cup", "hook", "dumbbell")
FEATURES = ("hole", "pocket", "boss", "knob", "fin", "handle")
#: a family's members: the first, larger or smaller, less a feature, one more
VARIANTS = ("a", "b", "c", "d")


def _frame(n: np.ndarray, rng: np.random.Generator) -> list[float]:
    """A rotation (row-major) whose third column is the unit vector ``n``, turned at random about it."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, helper)
    u /= math.sqrt(float(u @ u))
    v = np.cross(n, u)
    turn = rng.uniform(0.0, 2.0 * math.pi)
    a, b = math.cos(turn) * u + math.sin(turn) * v, -math.sin(turn) * u + math.cos(turn) * v
    return [a[0], b[0], n[0], a[1], b[1], n[1], a[2], b[2], n[2]]


def _segment(p: np.ndarray, q: np.ndarray, radius: float, rng) -> dict:
    d = q - p
    length = math.sqrt(float(d @ d))
    return {"op": "capsule", "center": list((p + q) / 2.0), "rot": _frame(d / length, rng),
            "half": length / 2.0, "radius": radius}


def _body(kind: str, rng: np.random.Generator) -> dict:
    """A body about the origin whose largest side is about 1."""
    u = rng.uniform
    if kind == "blob":
        parts = [{"op": "ellipsoid", "center": list(u(-0.25, 0.25, 3)), "rot": rotation(rng),
                  "radii": list(u(0.1, 0.28, 3))} for _ in range(int(rng.integers(3, 8)))]
        return {"op": "smooth", "k": u(0.06, 0.14), "parts": parts}
    if kind == "block":
        return {"op": "box", "half": [0.5, 0.5 * u(0.35, 1.0), 0.5 * u(0.3, 1.0)], "round": float(rng.choice([0.0, 0.015]))}
    if kind == "shaft":
        cuts = np.sort(u(-0.5, 0.5, int(rng.integers(1, 4))))
        edges = np.concatenate([[-0.5], cuts, [0.5]])
        return {"op": "union", "parts": [{"op": "cylinder", "center": [0.0, 0.0, (lo + hi) / 2.0], "radius": u(0.08, 0.3),
                                          "half": (hi - lo) / 2.0} for lo, hi in zip(edges[:-1], edges[1:]) if hi - lo > 0.04]}
    if kind == "plate":
        return {"op": "box", "half": [0.5, 0.5 * u(0.4, 1.0), u(0.015, 0.035)], "round": 0.0}
    if kind == "ring":
        minor = u(0.05, 0.12)
        return {"op": "torus", "major": 0.5 - minor, "minor": minor}
    if kind == "cup":
        radius, half, wall = u(0.25, 0.4), u(0.25, 0.45), u(0.025, 0.05)
        return {"op": "subtract", "parts": [{"op": "cylinder", "radius": radius, "half": half},
                                            {"op": "cylinder", "center": [0.0, 0.0, wall], "radius": radius - wall,
                                             "half": half}]}
    if kind == "hook":
        radius, points, heading = u(0.04, 0.08), [np.zeros(3)], np.array([1.0, 0.0, 0.0])
        for _ in range(int(rng.integers(3, 5))):
            turn = np.array(rotation(rng)).reshape(3, 3)
            heading = 0.5 * heading + 0.5 * (turn[:, 0])
            heading /= math.sqrt(float(heading @ heading))
            points.append(points[-1] + u(0.25, 0.4) * heading)
        middle = (np.min(points, axis=0) + np.max(points, axis=0)) / 2.0
        points = [p - middle for p in points]
        return {"op": "smooth", "k": 0.02, "parts": [_segment(p, q, radius, rng) for p, q in zip(points[:-1], points[1:])]}
    if kind == "dumbbell":
        r1, r2 = u(0.15, 0.25), u(0.15, 0.25)
        a, b = np.array([-0.5 + r1, 0.0, 0.0]), np.array([0.5 - r2, 0.0, 0.0])
        return {"op": "smooth", "k": 0.05, "parts": [{"op": "sphere", "center": list(a), "radius": r1},
                                                     {"op": "sphere", "center": list(b), "radius": r2},
                                                     _segment(a, b, u(0.05, 0.1), rng)]}
    raise ValueError(kind)


def _grid(lo, hi, cells: int) -> np.ndarray:
    """Points of a box's grid, x varying fastest (libigl's order)."""
    axes = [np.linspace(lo[k], hi[k], cells[k]) for k in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)


def _surface_point(body: dict, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A point of the body's surface, seen from its deepest point in a random direction, and its
    outward normal."""
    coarse = _grid((-0.7,) * 3, (0.7,) * 3, (29,) * 3)
    inside = coarse[int(np.argmin(distance(body, coarse)))]
    direction = rng.normal(size=3)
    direction /= math.sqrt(float(direction @ direction))
    steps = np.linspace(0.0, 1.5, 301)
    field = distance(body, inside + steps[:, None] * direction)
    first = int(np.argmax(field > 0.0))
    lo, hi = steps[max(first - 1, 0)], steps[first]
    for _ in range(40):
        mid = (lo + hi) / 2.0
        if distance(body, (inside + mid * direction)[None])[0] > 0.0:
            hi = mid
        else:
            lo = mid
    point = inside + lo * direction
    eps = 1e-4
    normal = np.array([distance(body, (point + e)[None])[0] - distance(body, (point - e)[None])[0]
                       for e in np.eye(3) * eps])
    return point, normal / math.sqrt(float(normal @ normal))


def _feature(kind: str, body: dict, rng: np.random.Generator) -> tuple[str, dict]:
    """A feature on the body's surface: how it joins (``union``, ``smooth``, ``subtract``) and its solid."""
    s, n = _surface_point(body, rng)
    u = rng.uniform
    if kind == "hole":
        return "subtract", {"op": "cylinder", "center": list(s), "rot": _frame(n, rng), "radius": u(0.03, 0.08), "half": 1.2}
    if kind == "pocket":
        return "subtract", {"op": "box", "center": list(s), "rot": _frame(n, rng),
                            "half": [u(0.06, 0.15), u(0.06, 0.15), u(0.04, 0.1)]}
    if kind == "boss":
        return "union", {"op": "cylinder", "center": list(s), "rot": _frame(n, rng), "radius": u(0.04, 0.1),
                         "half": u(0.05, 0.12)}
    if kind == "knob":
        return "smooth", {"op": "sphere", "center": list(s), "radius": u(0.06, 0.14)}
    if kind == "fin":
        reach = u(0.1, 0.2)
        return "union", {"op": "box", "center": list(s + n * (reach / 2.0 - 0.02)), "rot": _frame(n, rng),
                         "half": [u(0.08, 0.18), u(0.014, 0.025), reach / 2.0]}
    if kind == "handle":
        major, frame = u(0.1, 0.2), np.array(_frame(n, rng)).reshape(3, 3)
        centre = s - 0.3 * major * n
        ring = {"op": "torus", "center": list(centre), "rot": list(np.stack([n, frame[:, 1], frame[:, 0]], axis=1).ravel()),
                "major": major, "minor": u(0.02, 0.04)}
        keep = {"op": "halfspace", "center": list(centre), "rot": _frame(-n, rng)}
        return "union", {"op": "intersect", "parts": [ring, keep]}
    raise ValueError(kind)


def solid(body: dict, features: list[tuple[str, dict]]) -> dict:
    """The body with its features joined in order."""
    node = body
    for join, part in features:
        node = {"op": join, "parts": [node, part], **({"k": 0.03} if join == "smooth" else {})}
    return node


def _banded(node: dict, lo: np.ndarray, h: float, cells: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The grid's points (x fastest) and the field at them: exact within :data:`BAND` cells of the
    surface, read elsewhere from the nearest point of a grid :data:`STRIDE` times coarser (a point
    that far from the surface has the sign of its coarse neighbour, which is all marching cubes
    reads there, since the fields here change by at most their distance)."""
    points = _grid(lo, lo + h * (np.array(cells) - 1), cells)
    coarse_cells = [(n - 1) // STRIDE + 1 for n in cells]
    coarse = distance(node, _grid(lo, lo + h * STRIDE * (np.array(coarse_cells) - 1), coarse_cells))
    coarse = coarse.reshape(coarse_cells[::-1])
    near = [np.minimum((np.arange(n) + STRIDE // 2) // STRIDE, m - 1) for n, m in zip(cells, coarse_cells)]
    field = coarse[np.ix_(near[2], near[1], near[0])].ravel()
    band = np.abs(field) <= BAND * h
    field[band] = distance(node, points[band])
    return points, field


def surface_mesh(node: dict, size_mm: float):
    """The solid ``node`` as a closed triangle mesh whose largest side is ``size_mm``, as trimesh."""
    import igl
    import trimesh

    coarse_cells = 51
    coarse = _grid((-1.0,) * 3, (1.0,) * 3, (coarse_cells,) * 3)
    step = 2.0 / (coarse_cells - 1)
    near = coarse[distance(node, coarse) < step]              # inside, or a part thinner than a step
    lo, hi = near.min(axis=0) - 2 * step, near.max(axis=0) + 2 * step
    h = float(np.max(hi - lo)) / GRID
    cells = [STRIDE * int(math.ceil((hi[k] - lo[k]) / (h * STRIDE))) + 1 for k in range(3)]
    points, field = _banded(node, lo, h, cells)
    vertices, faces, _ = igl.marching_cubes(field, points, *cells, 0.0)
    mesh = trimesh.Trimesh(vertices, faces, process=False)     # closed as made: dropping its slivers opens it
    pieces = mesh.split(only_watertight=False)
    if len(pieces) > 1:
        mesh = max(pieces, key=lambda piece: piece.area)
    if mesh.volume < 0:
        mesh.invert()
    if len(mesh.faces) > FACES:                # shortest edges first, keeping the surface closed and its genus
        vertices, faces, _, _ = igl.decimate(np.asfortranarray(mesh.vertices),
                                             np.asfortranarray(mesh.faces, dtype=np.int32), FACES)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
    extent = float(np.max(np.ptp(mesh.vertices, axis=0)))
    centre = (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0)) / 2.0
    return trimesh.Trimesh((mesh.vertices - centre) * (size_mm / extent), mesh.faces, process=False)


def _family(seed: int, index: int) -> list[dict]:
    """The four members of family ``index``: name, variant, body, features and size each."""
    rng = np.random.default_rng([seed, index])
    kind = BODIES[int(rng.integers(len(BODIES)))]
    body = _body(kind, rng)
    count = int(rng.integers(1, 4))
    kinds = [FEATURES[int(k)] for k in rng.integers(len(FEATURES), size=count + 1)]
    features = [_feature(k, body, rng) for k in kinds]
    size = math.exp(rng.uniform(math.log(45.0), math.log(220.0)))
    factor = rng.uniform(1.2, 1.5)
    other = size * factor if size * factor <= SIZE_MM[1] else size / factor
    chosen = {"a": (count, size), "b": (count, other), "c": (count - 1, size), "d": (count + 1, size)}
    out = []
    for variant in VARIANTS:
        used, mm = chosen[variant]
        out.append({"name": f"g{index:04d}{variant}-{kind}", "family": index, "variant": variant, "body": kind,
                    "features": kinds[:used], "size_mm": mm, "solid": solid(body, features[:used])})
    return out


def family_of(name: str) -> str | None:
    """The family a generated model's name belongs to (``g0012b-ring`` -> ``g0012``), else None."""
    return name[:5] if len(name) > 6 and name[0] == "g" and name[1:5].isdigit() and name[5] in VARIANTS else None


def _write(job: tuple[dict, Path]) -> str:
    from ..io.atomic import write_bytes_atomic

    member, path = job
    if not path.is_file():
        mesh = surface_mesh(member["solid"], member["size_mm"])
        write_bytes_atomic(path, mesh.export(file_type="ply", encoding="binary"))
    return hashlib.sha256(path.read_bytes()).hexdigest()


def generate(out, *, count: int = 1000, seed: int = 0, jobs: int = 1, quiet: bool = True) -> list[Path]:
    """Write ``count`` generated meshes (PLY, millimetres) into ``out/v<VERSION>-s<seed>/``, with
    ``catalogue.json``, and return their paths, in order.  Files already there are kept (they were
    written whole), so a stopped run resumes."""
    from ..io.atomic import write_text_atomic
    from .common import run_parallel

    folder = Path(out) / f"v{VERSION}-s{seed}"
    members = [m for index in range(math.ceil(count / len(VARIANTS))) for m in _family(seed, index)][:count]
    paths = [folder / f"{m['name']}.ply" for m in members]
    folder.mkdir(parents=True, exist_ok=True)
    hashes = run_parallel(_write, list(zip(members, paths)), jobs=jobs, quiet=quiet, desc="catalogue")
    manifest = {"format": "tactrec-catalogue", "version": VERSION, "seed": seed, "faces": FACES, "grid": GRID,
                "models": [{k: m[k] for k in ("name", "family", "variant", "body", "features", "size_mm")}
                           | {"file": p.name, "sha256": h} for m, p, h in zip(members, paths, hashes)]}
    write_text_atomic(folder / "catalogue.json", json.dumps(manifest, indent=1) + "\n")
    return paths
