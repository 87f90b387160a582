"""Cleaning a scanned triangle mesh before it becomes a model (paper Section 5.1)."""

from __future__ import annotations

import numpy as np
from scipy import sparse

__all__ = ["clean_mesh", "STRAY_FRACTION"]

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


