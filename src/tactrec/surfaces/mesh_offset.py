"""A mesh offset outward by a round tip's radius, as the search of a tip's touch sees it.

A probe with a spherical tip of radius ``r`` records the tip's centres: points
of the surface offset outward by ``r`` (:mod:`tactrec.tip`).  The search
(:mod:`tactrec.methods.fast_stages`) treats such a touch as a plain touch of
that offset surface, so nothing of the data is moved along a normal it does
not know.  :class:`OffsetMesh` is what the search reads of a mesh, offset:

* **places**: each vertex ``v`` lifted to ``v + r n`` along its fitted normal
  ``n`` (the point of the offset surface whose closest surface point is ``v``);
* **curvatures**: each principal curvature ``kappa -> kappa / (1 - r kappa)``
  (convex negative, outward normal: a radius ``rho`` becomes ``rho + r``
  where convex, ``rho - r`` where concave); directions and normals are
  shared.  A vertex in a hollow tighter than the tip (``r kappa >= 1``) is
  no place a tip's centre reaches: its curvatures are infinite, so it ranks
  last in every lookup;
* **distance field**: the signed distance minus ``r``, sampled like the
  model's own (:func:`tactrec.surfaces.mesh_field.build_field` with
  ``offset``).  A database built with the tip's radius stores it
  (:func:`offset_arrays`, ``tactrec build --tip-radius``); else it is built
  on first use (seconds for a scan) and kept with the model.

It is an :class:`~tactrec.surfaces.offset.Offset`: its exact distances and
planes are the model's minus ``r``; everything else (the triangles, exact
closest points, the name) is the model's.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from .mesh_curvature import CurvatureField
from .mesh_field import DistanceField, build_field
from .offset import Offset

__all__ = ["OffsetMesh", "offset_curvature", "offset_arrays", "stored_offset_field"]


def offset_curvature(k: np.ndarray, r: float) -> np.ndarray:
    """Principal curvatures ``k (...)`` of a surface, those of its offset by ``r`` outward
    (``k / (1 - r k)``; ``inf`` where ``r k >= 1``, a hollow tighter than the offset)."""
    k = np.asarray(k, dtype=np.float64)
    den = 1.0 - r * k
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, k / np.where(den > 0, den, 1.0), np.inf)


class OffsetMesh(Offset):
    """The mesh ``model`` offset outward by ``radius`` (module text): an :class:`Offset` of one radius
    whose places, curvatures and distance field are the offset's too."""

    def __init__(self, model, radius: float):
        super().__init__(model, float(radius))

    @cached_property
    def vertices(self) -> np.ndarray:
        """``(n, 3)``: each vertex lifted by the radius along its fitted normal."""
        f = self.model.fine_curvatures
        return self.model.vertices + self.radius * f.normal

    @cached_property
    def bounds(self) -> np.ndarray:
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @cached_property
    def fine_curvatures(self) -> CurvatureField:
        f = self.model.fine_curvatures
        return CurvatureField(offset_curvature(f.k1, self.radius), offset_curvature(f.k2, self.radius), f.d1,
                              f.normal, f.radius)

    @cached_property
    def distance_field(self) -> DistanceField:
        m = self.model
        stored = stored_offset_field(getattr(m, "_stored_field", None), self.radius)
        if stored is not None:
            return stored
        return build_field(m.vertices, m.faces, mean_edge=m.mean_edge, spacing=m.distance_field.spacing,
                           offset=self.radius)

    def __repr__(self) -> str:
        return f"OffsetMesh({self.model!r}, {self.radius!r})"


def offset_arrays(model, radii) -> dict[str, np.ndarray]:
    """The offset fields of a mesh ``model`` for each of ``radii`` (model units), as a database
    stores them: ``offset_radii (k,)`` and each field's arrays under ``offset<i>_<key>``."""
    radii = np.unique(np.asarray(radii, dtype=np.float64))
    out = {"offset_radii": radii}
    for i, r in enumerate(radii):
        out.update({f"offset{i}_{k}": v for k, v in model.offset(float(r)).distance_field.to_store().items()})
    return out


def stored_offset_field(arrays, radius: float) -> DistanceField | None:
    """The field of the offset by ``radius`` among a model's stored ``arrays`` (:func:`offset_arrays`),
    None where it is not stored.  ``ValueError`` where it is malformed."""
    if arrays is None or "offset_radii" not in arrays:
        return None
    radii = np.asarray(arrays["offset_radii"], dtype=np.float64).reshape(-1)
    match = np.flatnonzero(np.isclose(radii, radius, rtol=1e-9, atol=0.0))
    if not len(match):
        return None
    i = int(match[0])
    return DistanceField.from_store({k: arrays[f"offset{i}_{k}"] for k in DistanceField.KEYS})
