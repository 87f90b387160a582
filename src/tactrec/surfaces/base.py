"""What every surface model answers, whatever its representation.

A closed-form surface and a triangle mesh answer the same questions:

* :meth:`SurfaceModel.table_samples` -- surface points with their outward
  normals and principal curvatures, the rows of a lookup table (Section 3.2.1);
* :meth:`SurfaceModel.distance` -- distance of points to the surface (eq. 8);
* :meth:`SurfaceModel.planes` -- signed distances and the planes they are
  measured against, what a point-to-plane step linearises;
* :meth:`SurfaceModel.plane_section` -- points of a plane section at equal
  arc-length spacing, for simulated touches (Sections 4.3 and 5.4).

Curvature sign convention: normals point out of the object and a normal
curvature is ``k = c'' . n``, so a convex surface has negative curvatures.
``k1 >= k2`` always.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import ClassVar

import numpy as np

__all__ = ["SurfaceModel", "TableSamples", "SiteFrame"]


@dataclasses.dataclass(frozen=True)
class TableSamples:
    """Rows of a curvature lookup table.

    Attributes
    ----------
    sites : (n, s) float
        Model-specific location of each row: ``(u, v)`` for a closed-form
        surface, the vertex index for a mesh.
    positions : (n, 3) float
        Surface points, model frame.
    normals : (n, 3) float
        Outward unit normals.
    k1, k2 : (n,) float
        Principal curvatures, ``k1 >= k2``.
    """

    sites: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    k1: np.ndarray
    k2: np.ndarray

    def __len__(self) -> int:
        return len(self.k1)


@dataclasses.dataclass(frozen=True)
class SiteFrame:
    """A surface point with an orthonormal frame ``[d1 d2 n]``, ``d1 x d2 = n``."""

    site: np.ndarray
    point: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normal: np.ndarray


class SurfaceModel(abc.ABC):
    """Abstract surface model.  Subclasses set ``kind`` and implement the rest."""

    kind: ClassVar[str] = "abstract"

    name: str
    units: str | None
    source_hash: str

    @abc.abstractmethod
    def table_samples(self, *, resolution: int | None = None, rng=None) -> TableSamples:
        """Surface points, normals and principal curvatures for a lookup table."""

    @abc.abstractmethod
    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance of ``points`` ``(..., 3)`` to the surface, shape ``(...)``."""

    @abc.abstractmethod
    def planes(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed distances ``(...)`` of ``points (..., 3)`` to the surface (positive outside) and the
        unit normals ``(..., 3)`` of the planes they are measured against: what a point-to-plane
        step linearises (:mod:`tactrec.registration.solver`).  Not finite where the surface gives
        no plane."""

    def projected(self, points: np.ndarray, passes: int = 2) -> np.ndarray:
        """``points (n, 3)`` moved onto the surface: ``passes`` steps along the planes' normals by
        their signed distances (:meth:`planes`; closest points, to well within a facet's or the
        implicit function's error after two)."""
        x = np.asarray(points, dtype=np.float64)
        for _ in range(passes):
            dist, normals = self.planes(x)
            x = x - np.asarray(dist)[:, None] * np.asarray(normals)
        return x

    @abc.abstractmethod
    def site_frame(self, site: np.ndarray) -> SiteFrame:
        """Point, outward normal and tangent frame at a site."""

    def site_points(self, sites) -> tuple[np.ndarray, np.ndarray]:
        """Points and outward unit normals ``(n, 3)`` of ``sites`` (rows as :meth:`random_sites` gives)."""
        frames = [self.site_frame(s) for s in sites]
        return (np.array([f.point for f in frames]).reshape(-1, 3), np.array([f.normal for f in frames]).reshape(-1, 3))

    @abc.abstractmethod
    def locate(self, point: np.ndarray) -> np.ndarray:
        """The site of the surface point nearest to ``point`` ``(3,)``."""

    @abc.abstractmethod
    def plane_section(self, site: np.ndarray, tangent: np.ndarray, *,
                      spacing: float, count: int) -> np.ndarray:
        """Points ``(count, 3)`` along the section of the surface by the plane
        through the site's point spanned by its normal and ``tangent``, at equal
        arc-length ``spacing``, centred on the site's point and ordered along
        ``tangent``.  Raises ``ValueError`` if the section leaves the surface."""

    @abc.abstractmethod
    def random_sites(self, count: int, *, rng=None) -> np.ndarray:
        """``count`` random sites, roughly uniform over the surface."""

    @property
    @abc.abstractmethod
    def size(self) -> float:
        """Diagonal of the bounding box, model units."""
