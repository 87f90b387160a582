"""Near-duplicates, the ``near-duplicates`` set of ``tactrec bench multi-touch``: each of the ten
``paper-fig11`` scans beside a copy of itself with one bump, where only a touch of the bump tells
them apart.

The bump (:func:`bumped`) is :data:`HEIGHT` high and :data:`WIDTH` across, raised along the vertex
normals with a cosine-squared profile, centred at a vertex of the scan drawn at random (seeded, one
per scan) among those with at least :data:`BUMP_VERTICES` vertices under the bump.  A session
touches the original (even instances) or the copy (odd ones); its first touch is ``hard-10``'s
(12 mm curves 30 degrees apart, noise 0.05 mm, no outward side) at a random place between
:data:`NEAR` and :data:`FAR` of the bump's centre, on its side (normals within 60 degrees), so that
the first touch does not reach the bump and a later one within ``multi_touch.RADIUS`` can.  A touch
that does not cover the bump fits both models alike, so random places decide only when they land
on it, and a ``next`` that aims where the two surfaces differ decides at once.  The copies are made
on demand from the seed, never stored.
"""

from __future__ import annotations

import numpy as np

from ..simulation import simulate_touch
from .common import instance_rng, random_face_site

__all__ = ["HEIGHT", "WIDTH", "NEAR", "FAR", "family", "first_touch", "bumped"]

#: the bump: height and width (mm), and the least vertices it must raise
HEIGHT, WIDTH, BUMP_VERTICES = 3.0, 10.0, 12
#: the first touch's contact lies this far from the bump's centre (mm)
NEAR, FAR = 15.0, 35.0


def bumped(model, centre: int, *, height: float = HEIGHT, width: float = WIDTH):
    """A copy of mesh ``model`` with a bump at vertex ``centre``: vertices within ``width / 2`` of
    it, on its side (normals within 90 degrees of its: not the far face of a thin wall), raised
    along their normals by ``height cos^2(pi r / width)``."""
    from ..surfaces.mesh import MeshModel

    v = np.asarray(model.vertices, dtype=np.float64).copy()
    r = np.linalg.norm(v - v[centre], axis=1)
    normals = np.asarray(model.vertex_normals, dtype=np.float64)
    under = (r < 0.5 * width) & (normals @ normals[centre] > 0.0)
    v[under] += (height * np.cos(np.pi * r[under] / width) ** 2)[:, None] * normals[under]
    return MeshModel(v, model.faces, name=f"{model.name}+bump", units=model.units)


def _centre(model, m_index: int, seed: int) -> int:
    """The bump's vertex: drawn at random among those with enough vertices under the bump."""
    rng = instance_rng(seed, m_index, 0, 91)
    v = np.asarray(model.vertices, dtype=np.float64)
    for _ in range(200):
        c = int(rng.integers(len(v)))
        if np.count_nonzero(np.linalg.norm(v - v[c], axis=1) < 0.5 * WIDTH) >= BUMP_VERTICES:
            return c
    raise RuntimeError(f"no vertex of {model.name} has {BUMP_VERTICES} vertices within {WIDTH / 2:g} mm")


def family(entry, m_index: int, seed: int, cache: dict) -> tuple[list, int]:
    """The set's database for scan ``entry``: ``[original, copy with a bump]`` (entries) and the bump's
    vertex; kept in ``cache`` for the process."""
    from ..recognition import ModelEntry
    from ..tables import CurvatureTable

    key = (entry.name, m_index, seed)
    if key not in cache:
        centre = _centre(entry.model, m_index, seed)
        copy = bumped(entry.model, centre)
        cache[key] = ([entry, ModelEntry(copy, CurvatureTable(copy.table_samples()))], centre)
    return cache[key]


def first_touch(entries: list, centre: int, m_index: int, instance: int, seed: int, spec: dict, spacing: float):
    """The session's truth (an entry of ``entries``) and its first touch: ``spec``'s curves at a random
    face site between :data:`NEAR` and :data:`FAR` of the bump's centre, on its side."""
    truth = entries[instance % 2]
    model = truth.model
    rng = instance_rng(seed, m_index, instance, 92)
    p = np.asarray(entries[0].model.vertices[centre], dtype=np.float64)
    n = np.asarray(entries[0].model.vertex_normals[centre], dtype=np.float64)
    points = int(round(spec["length"] / spacing)) + 1
    for _ in range(5000):
        site = random_face_site(model, rng)
        frame = model.site_frame(site)
        if not NEAR <= np.linalg.norm(frame.point - p) <= FAR or frame.normal @ n < 0.5:
            continue
        try:
            return truth, simulate_touch(model, site, points=points, spacing=spacing, angle=spec["angle"],
                                         noise=spec["noise"], noise_kind="gaussian", outward=spec["outward"], rng=rng)
        except ValueError:
            continue
    raise RuntimeError(f"no place of {model.name} {NEAR:g}-{FAR:g} mm from the bump takes a touch")
