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
* **distance field**: the signed distance minus ``r``.  No tip up to
  :data:`REACH` needs a build: a field sampled at ``d`` reads the offset as
  ``d - r`` (:meth:`~tactrec.surfaces.mesh_field.DistanceField.shifted`),
  and the trilinear interpolation of ``d - r`` is that of ``d`` less ``r``,
  so within the band the shift leaves it is, sample for sample, the field a
  build of the offset on that grid would give.  Which field serves a radius
  (:func:`tip_field`):

  - the field stored for that radius, where a database was built with it
    (:func:`offset_arrays`, ``tactrec build --tip-radius``): the model's
    own spacing and band about the offset surface;
  - the model's own field, where ``r`` leaves at least half its band
    (``r <= truncation / 2``);
  - else the *outer field* (:func:`outer_field`), which every database
    stores: the signed distance from ``-BAND`` cells inside to ``REACH``
    plus ``BAND`` cells outside, its cells ``REACH / OUTER_CELLS`` wide (or
    the model's own, where coarser).  Every tip up to ``REACH`` keeps a band
    of ``BAND`` of its cells.  The offset of a tip of radius ``r`` bends no
    tighter than ``r`` where convex, so the coarser cells cost it about
    ``h^2 / 8 r`` of interpolation (``tactrec bench sensor`` measures what
    that does to recognition);
  - a larger tip's offset is built on first use (seconds for a scan).

  Each is kept with the model once read.

It is an :class:`~tactrec.surfaces.offset.Offset`: its exact distances and
planes are the model's minus ``r``; everything else (the triangles, exact
closest points, the name) is the model's.
"""

from __future__ import annotations

import dataclasses
from functools import cached_property

import numpy as np

from ..units import conversion
from .mesh_curvature import CurvatureField
from .mesh_field import BAND, DistanceField, build_field
from .offset import Offset

__all__ = ["OffsetMesh", "offset_curvature", "offset_arrays", "stored_offset_field", "outer_field", "outer_arrays",
           "tip_field", "REACH", "OUTER_CELLS"]

#: the largest tip the stored fields serve, in millimetres (in the model's units; taken as they are
#: where the model does not say its units)
REACH = 10.0
#: cells of the outer field across ``REACH`` (where the model's own cells are finer)
OUTER_CELLS = 8
#: the names the outer field is stored under, and the offset its samples are taken from
OUTER_KEYS = tuple(f"outer_{k}" for k in DistanceField.KEYS) + ("outer_offset",)


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
        return tip_field(self.model, self.radius)

    def __repr__(self) -> str:
        return f"OffsetMesh({self.model!r}, {self.radius!r})"


def offset_arrays(model, radii) -> dict[str, np.ndarray]:
    """The offset fields of a mesh ``model`` for each of ``radii`` (model units), as a database
    stores them: ``offset_radii (k,)`` and each field's arrays under ``offset<i>_<key>``."""
    radii = np.unique(np.asarray(radii, dtype=np.float64))
    out = {"offset_radii": radii}
    for i, r in enumerate(radii):
        field = stored_offset_field(getattr(model, "_stored_field", None), float(r)) or _built(model, float(r))
        out.update({f"offset{i}_{k}": v for k, v in field.to_store().items()})
    return out


def _built(model, radius: float) -> DistanceField:
    """The field of ``model`` offset by ``radius``, built at the model's own spacing and band."""
    return build_field(model.vertices, model.faces, mean_edge=model.mean_edge, spacing=model.distance_field.spacing,
                       offset=radius)


def _reach(model) -> float:
    """:data:`REACH` in the model's units."""
    return REACH * conversion("mm", model.units)


def outer_field(model) -> DistanceField:
    """The outer field of a mesh ``model`` (module text): sampled about the surface offset by half the
    reach, with a band that covers every tip up to the reach with ``BAND`` cells to spare, and
    shifted back so that it reads the signed distance itself.  Read from the database where it is
    stored (:func:`outer_arrays`), else built."""
    stored = getattr(model, "_stored_field", None)
    if stored is not None and OUTER_KEYS[0] in stored:
        field = DistanceField.from_store({k: stored[f"outer_{k}"] for k in DistanceField.KEYS})
        return field.shifted(-float(stored["outer_offset"]))
    reach = _reach(model)
    h = max(model.distance_field.spacing, reach / OUTER_CELLS)
    field = build_field(model.vertices, model.faces, mean_edge=model.mean_edge, spacing=h,
                        band=BAND + int(np.ceil(0.5 * reach / h)), offset=0.5 * reach)
    return field.shifted(-0.5 * reach)


def outer_arrays(model) -> dict[str, np.ndarray]:
    """The outer field of a mesh ``model`` as a database stores it (:data:`OUTER_KEYS`): its samples and
    the offset they were taken about."""
    field = model.outer_field
    arrays = dataclasses.replace(field, shift=0.0).to_store()
    return {**{f"outer_{k}": v for k, v in arrays.items()}, "outer_offset": np.array(-field.shift)}


def tip_field(model, radius: float) -> DistanceField:
    """The field a search of a tip of ``radius`` reads on a mesh ``model`` (module text)."""
    stored = stored_offset_field(getattr(model, "_stored_field", None), radius)
    if stored is not None:
        return stored
    own = model.distance_field
    if radius <= 0.5 * own.truncation:
        return own.shifted(radius)
    if radius <= _reach(model):
        return model.outer_field.shifted(radius)
    return _built(model, radius)


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
