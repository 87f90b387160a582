"""Reading a mesh file and cleaning a scanned triangle mesh before it becomes a model (paper Section 5.1)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import sparse

__all__ = ["clean_mesh", "read_mesh", "STRAY_FRACTION"]

#: components with fewer than this fraction of the faces are dropped as strays
STRAY_FRACTION = 0.01


def clean_mesh(vertices: np.ndarray, faces: np.ndarray):
    """Merge duplicate vertices, drop degenerate, repeated and out-of-range
    faces and stray components (under 1 % of the faces), remove unreferenced
    vertices.  Returns ``vertices, faces, report``."""
    report = {"vertices_in": int(len(vertices)), "faces_in": int(len(faces))}
    bad = (faces < 0) | (faces >= len(vertices))
    if bad.any():
        faces = faces[~bad.any(axis=1)]
        report["faces_out_of_range"] = int(bad.any(axis=1).sum())
    scale = float(np.ptp(vertices, axis=0).max()) or 1.0
    key = np.round(vertices / (scale * 1e-9)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    report["duplicate_vertices_merged"] = int(len(vertices) - len(first))
    vertices = vertices[first]
    faces = inverse[faces]
    tri = vertices[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2]) \
        | (area2 <= 1e-12 * scale * scale)
    report["degenerate_faces_dropped"] = int(degenerate.sum())
    faces = faces[~degenerate]
    _, unique = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    report["repeated_faces_dropped"] = int(len(faces) - len(unique))
    faces = faces[np.sort(unique)]
    if len(faces):
        # components by shared vertices
        n = len(vertices)
        m = len(faces)
        inc = sparse.csr_matrix((np.ones(3 * m), (np.repeat(np.arange(m), 3), faces.ravel())), shape=(m, n))
        graph = sparse.bmat([[None, inc], [inc.T, None]]).tocsr()
        ncomp, labels = sparse.csgraph.connected_components(graph, directed=False)
        face_labels = labels[:m]
        counts = np.bincount(face_labels, minlength=ncomp)
        keep_comp = counts >= max(1, STRAY_FRACTION * m)
        keep = keep_comp[face_labels]
        report["stray_components_dropped"] = int(np.sum((counts > 0) & ~keep_comp))
        report["stray_faces_dropped"] = int((~keep).sum())
        faces = faces[keep]
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    report["unreferenced_vertices_removed"] = int((~used).sum())
    vertices = vertices[used]
    faces = remap[faces]
    report["vertices"] = int(len(vertices))
    report["faces"] = int(len(faces))
    return vertices, faces, report


def read_mesh(path, *, units: str | None = None, scale: float | None = None):
    """A mesh file read with trimesh and cleaned (:func:`clean_mesh`): ``(vertices, faces, report,
    units, scale, sha256)``, the vertices multiplied by ``scale`` and ``units`` those they are then
    in (None where no known unit is).  A file that is missing, empty, unreadable, without triangles
    or with coordinates that are not finite is an :class:`~tactrec.errors.InputError` naming it."""
    import hashlib

    import trimesh

    from ..errors import InputError
    from ..units import UNITS, unit_scale

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path)
    if units is not None:
        try:
            unit_scale(units)
        except ValueError as exc:
            raise InputError(str(exc), path) from None
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be a positive number, got {scale!r}", path)
    blob = path.read_bytes()
    if not blob.strip():
        raise InputError("empty file", path)
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds on a broken file
        raise InputError(f"cannot read mesh ({exc.__class__.__name__}: {str(exc)[:120]})", path) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0 or len(mesh.vertices) < 3:
        raise InputError("no triangles in the file", path)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        raise InputError("vertex coordinates are not finite", path)
    vertices, faces, report = clean_mesh(vertices, np.asarray(mesh.faces, dtype=np.int64))
    if len(faces) == 0:
        raise InputError("degenerate mesh: no triangle with a non-zero area", path)
    factor = 1.0 if scale is None else float(scale)
    out_units = units
    if scale is not None and units is not None:
        # name the units the scaled coordinates are in, when it is a known one
        target = unit_scale(units) / factor
        out_units = next((u for u, s in UNITS.items() if np.isclose(s, target, rtol=1e-9)), None)
    return vertices * factor, faces, report, out_units, factor, hashlib.sha256(blob).hexdigest()
