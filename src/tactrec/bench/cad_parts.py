"""Machined parts with sharp edges and flat faces, made by code: the CAD half of ``--scans other``.

Scans are smooth almost everywhere; a machined part is flat almost
everywhere and sharp at its edges, where a touch's curves bend through a
right angle within a fraction of a millimetre.  These ten parts are built
here with trimesh's extrusions and solids of revolution (no file is read
or fetched), from fixed dimensions in millimetres, then split as a CAD
exporter with a largest edge would split them
(:func:`trimesh.remesh.subdivide_to_size`, which moves no point of the
surface).  Nothing in the method is tuned on them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PARTS", "CAD", "part_mesh", "MAX_EDGE"]

#: the largest edge of the exported triangles, mm
MAX_EDGE = 3.0


def _extruded(cells: list[tuple[int, int]], xs: list[float], ys: list[float], height: float):
    """A prism over the union of grid cells ``(i, j)`` (``[xs[i], xs[i+1]] x [ys[j], ys[j+1]]``),
    ``height`` tall: its cap triangulated cell by cell, so that cells share whole edges."""
    from trimesh.creation import extrude_triangulation

    index: dict[tuple[int, int], int] = {}

    def corner(i, j):
        return index.setdefault((i, j), len(index))

    faces = []
    for i, j in cells:
        a, b, c, d = corner(i, j), corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)
        faces += [[a, b, c], [a, c, d]]
    points = np.array([[xs[i], ys[j]] for (i, j) in sorted(index, key=index.get)], dtype=np.float64)
    return extrude_triangulation(points, np.array(faces), height)


def _revolved(profile: list[tuple[float, float]]):
    """The solid swept by a ``(radius, height)`` profile about the z axis (128 sections): from the axis
    back to it, or a loop off the axis (closed here)."""
    from trimesh.creation import revolve

    line = np.array(profile, dtype=np.float64)
    if line[0, 0] > 0:
        line = np.vstack([line, line[:1]])
    return revolve(line, sections=128)


def _prism(polygon: list[tuple[float, float]], height: float):
    """A convex polygon (counter-clockwise) extruded ``height``: its cap fanned from the first corner."""
    from trimesh.creation import extrude_triangulation

    n = len(polygon)
    faces = np.array([[0, k, k + 1] for k in range(1, n - 1)])
    return extrude_triangulation(np.array(polygon, dtype=np.float64), faces, height)


def _frustum(base: float, top: float, height: float):
    """A square frustum: base and top squares ``base`` and ``top`` mm a side."""
    import trimesh

    b, t = base / 2.0, top / 2.0
    corners = [(x, y, 0.0) for x, y in ((-b, -b), (b, -b), (b, b), (-b, b))] + \
              [(x, y, height) for x, y in ((-t, -t), (t, -t), (t, t), (-t, t))]
    return trimesh.convex.convex_hull(np.array(corners))


def _box(x: float, y: float, z: float):
    from trimesh.creation import box

    return box(extents=(x, y, z))


def _hexagonal(radius: float, height: float):
    from trimesh.creation import cylinder

    return cylinder(radius=radius, height=height, sections=6)


#: name -> how it is made
PARTS = {
    "block": lambda: _box(60.0, 40.0, 25.0),
    "hex_bar": lambda: _hexagonal(18.0, 55.0),
    "shaft": lambda: _revolved([(0, 0), (10, 0), (10, 30), (16, 30), (16, 50), (8, 50), (8, 75), (0, 75)]),
    "flange": lambda: _revolved([(8, 0), (30, 0), (30, 6), (14, 6), (14, 20), (8, 20)]),
    "tube": lambda: _revolved([(18, 0), (20, 0), (20, 60), (18, 60)]),
    "l_bracket": lambda: _extruded([(0, 0), (1, 0), (0, 1)], [0, 6, 50], [0, 6, 40], 30.0),
    "u_channel": lambda: _extruded([(0, 0), (1, 0), (2, 0), (0, 1), (2, 1)], [0, 6, 34, 40], [0, 6, 30], 45.0),
    "t_slot": lambda: _extruded([(0, 1), (1, 1), (2, 1), (1, 0)], [0, 18, 30, 48], [0, 30, 40], 35.0),
    "wedge": lambda: _prism([(0, 0), (50, 0), (0, 25)], 30.0),
    "frustum": lambda: _frustum(50.0, 20.0, 35.0),
}
#: their names, in order
CAD = tuple(PARTS)


def part_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The part ``name``'s vertices ``(n, 3)`` (mm) and faces ``(f, 3)``, split to edges of at most
    :data:`MAX_EDGE`."""
    import trimesh

    mesh = PARTS[name]()
    vertices, faces = trimesh.remesh.subdivide_to_size(np.asarray(mesh.vertices, dtype=np.float64),
                                                       np.asarray(mesh.faces), max_edge=MAX_EDGE)
    mesh = trimesh.Trimesh(vertices, faces, process=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
