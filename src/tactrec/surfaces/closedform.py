"""Closed-form surfaces: a parametrisation sigma(u, v) and an implicit f = 0 (Section 4).

A surface is declared in a TOML file (see docs/formats.md)::

    name = "torus"
    units = "mm"                       # optional
    parameters = { R = 2.0, r = 0.5 }

    [parametric]
    x = "(R + r*cos(v))*cos(u)"
    y = "(R + r*cos(v))*sin(u)"
    z = "r*sin(v)"
    u = [0, "2*pi"]
    v = [0, "2*pi"]
    periodic = ["u", "v"]

    [implicit]                         # f > 0 outside
    f = "(sqrt(x**2 + y**2) - R)**2 + z**2 - r**2"

    [table]                            # optional
    resolution = [120, 60]

The file is parsed, and its expressions differentiated and compiled, by
:mod:`tactrec.surfaces.closedform_spec`.

Normals point outward, the direction of ``grad f``: where ``sigma_u x sigma_v``
points the other way, it is flipped (point by point).
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import tomllib
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..linalg import dot3, norm3, rotate
from .base import SiteFrame, SurfaceModel, TableSamples
from .closedform_sections import project_out, trace_sections, unit_vectors
from .closedform_spec import Domain, parse_spec

__all__ = ["ClosedFormSurface", "Domain", "FrameJet"]

@dataclasses.dataclass(frozen=True)
class FrameJet:
    """The moving frame at parameter points and its first derivatives.

    All arrays have leading shape ``(...)`` of the (u, v) inputs.

    Attributes
    ----------
    point : (..., 3)        sigma(u, v)
    su, sv : (..., 3)       first partial derivatives of sigma
    frame : (..., 3, 3)     columns d1, d2, n (outward), ``d1 = su/|su|``
    frame_u, frame_v : (..., 3, 3)  derivatives of ``frame``
    regular : (...,) bool   False where the parametrisation is singular
    """

    point: np.ndarray
    su: np.ndarray
    sv: np.ndarray
    frame: np.ndarray
    frame_u: np.ndarray
    frame_v: np.ndarray
    regular: np.ndarray


class ClosedFormSurface(SurfaceModel):
    """A surface given by sigma(u, v) and f(x, y, z) = 0 (paper Section 4).

    Build one with :meth:`from_file` or :meth:`from_text`.
    """

    kind = "closed-form"

    def __init__(self, spec: dict, *, text: str, source: str, name: str | None = None):
        self.source = source
        self.text = text
        self.source_hash = hashlib.sha256(text.encode("utf-8")).hexdigest()
        try:
            self._parse(spec, name)
        except InputError:
            raise
        except (ValueError, TypeError, KeyError) as exc:
            reason = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc  # KeyError's str() adds quotes
            raise InputError(str(reason), source) from None

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_file(cls, path: str | os.PathLike) -> "ClosedFormSurface":
        """Load a TOML surface file.  Raises :class:`InputError` on any problem."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise InputError("no such file", path) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read file ({exc.__class__.__name__})", path) from None
        return cls.from_text(text, source=str(path), name=path.stem)

    @classmethod
    def from_text(cls, text: str, *, source: str = "<surface>", name: str | None = None) -> "ClosedFormSurface":
        """Parse TOML ``text``; ``name`` is used when the file sets none."""
        if not text.strip():
            raise InputError("empty file", source)
        try:
            spec = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"not valid TOML ({exc})", source) from None
        return cls(spec, text=text, source=source, name=name)

    def _parse(self, spec: dict, default_name: str | None) -> None:
        p = parse_spec(spec, default_name)
        self.name, self.units, self.description, self.parameters = p.name, p.units, p.description, p.parameters
        self.domain_u, self.domain_v, self.symmetries, self.resolution = p.domain_u, p.domain_v, p.symmetries, p.resolution
        self._sigma, self._jet, self._f, self._f_grad, self._f_hess = p.sigma, p.jet, p.f, p.f_grad, p.f_hess

    # ------------------------------------------------------------------ geometry
    def evaluate(self, u, v) -> np.ndarray:
        """sigma(u, v), shape ``(..., 3)``."""
        return self._sigma(u, v)

    def _derivatives(self, u, v):
        jet = self._jet(u, v)
        return tuple(jet[..., 3 * i: 3 * i + 3] for i in range(6))

    def _orientation(self, point: np.ndarray, m: np.ndarray) -> np.ndarray:
        """+1 where ``m`` (sigma_u x sigma_v) points along grad f, else -1."""
        g = self._f_grad(point[..., 0], point[..., 1], point[..., 2])[..., 1:]
        return np.where(np.sum(g * m, axis=-1) < 0, -1.0, 1.0)

    def frame_jet(self, u, v) -> FrameJet:
        """Frame ``[d1 d2 n]`` at (u, v) and its analytic u and v derivatives."""
        with np.errstate(all="ignore"):
            return self._frame_jet(u, v)

    def _frame_jet(self, u, v) -> FrameJet:
        s, su, sv, suu, suv, svv = self._derivatives(u, v)
        d1, su_norm = unit_vectors(su)
        m = np.cross(su, sv)
        n_hat, m_norm = unit_vectors(m)
        sign = self._orientation(s, m)[..., None]
        n = sign * n_hat
        d2 = np.cross(n, d1)
        with np.errstate(all="ignore"):
            d1_u = project_out(d1, suu) / su_norm[..., None]
            d1_v = project_out(d1, suv) / su_norm[..., None]
            m_u = np.cross(suu, sv) + np.cross(su, suv)
            m_v = np.cross(suv, sv) + np.cross(su, svv)
            n_u = sign * project_out(n_hat, m_u) / m_norm[..., None]
            n_v = sign * project_out(n_hat, m_v) / m_norm[..., None]
        d2_u = np.cross(n_u, d1) + np.cross(n, d1_u)
        d2_v = np.cross(n_v, d1) + np.cross(n, d1_v)
        frame = np.stack([d1, d2, n], axis=-1)
        frame_u = np.stack([d1_u, d2_u, n_u], axis=-1)
        frame_v = np.stack([d1_v, d2_v, n_v], axis=-1)
        scale = np.linalg.norm(su, axis=-1) * np.linalg.norm(sv, axis=-1)
        regular = (m_norm > 1e-9 * scale) & (su_norm > 0) & np.all(np.isfinite(frame_u), axis=(-2, -1)) \
            & np.all(np.isfinite(frame_v), axis=(-2, -1))
        return FrameJet(s, su, sv, frame, frame_u, frame_v, regular)

    def curvatures(self, u, v):
        """Principal curvatures ``k1 >= k2`` and the outward normal at (u, v).

        The eigenvalues of ``FI^-1 FII`` (Section 4.1).  Returns ``(k1, k2,
        normal, regular)``.
        """
        s, su, sv, suu, suv, svv = self._derivatives(u, v)
        m = np.cross(su, sv)
        n_hat, m_norm = unit_vectors(m)
        n = self._orientation(s, m)[..., None] * n_hat
        E = np.sum(su * su, -1)
        F = np.sum(su * sv, -1)
        G = np.sum(sv * sv, -1)
        L = np.sum(suu * n, -1)
        M = np.sum(suv * n, -1)
        N = np.sum(svv * n, -1)
        with np.errstate(all="ignore"):
            det = E * G - F * F
            H = (E * N - 2 * F * M + G * L) / (2 * det)
            K = (L * N - M * M) / det
            root = np.sqrt(np.maximum(H * H - K, 0.0))
        regular = (m_norm > 1e-9 * np.sqrt(E * G)) & np.isfinite(H) & np.isfinite(K)
        return H + root, H - root, n, regular

    def implicit(self, points: np.ndarray, order: int = 0) -> np.ndarray:
        """f (order 0), [f, grad f] (order 1) or [f, grad f, hessian entries] (order 2).

        Returns ``(..., 1)``, ``(..., 4)`` or ``(..., 10)``; the Hessian entries
        are ``xx, xy, xz, yy, yz, zz``.
        """
        fn = (self._f, self._f_grad, self._f_hess)[order]
        return fn(points[..., 0], points[..., 1], points[..., 2])

    def distance(self, points: np.ndarray) -> np.ndarray:
        """First-order distance ``|f| / |grad f|`` (eq. 11)."""
        fg = self.implicit(np.asarray(points, dtype=np.float64), order=1)
        with np.errstate(all="ignore"):
            return np.abs(fg[..., 0]) / np.linalg.norm(fg[..., 1:], axis=-1)

    def planes(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed first-order distances ``f / |grad f|`` ``(...)`` (eq. 11) and unit normals
        ``grad f / |grad f|`` ``(..., 3)`` of ``points (..., 3)``; not finite where ``grad f`` vanishes."""
        fg = self.implicit(np.asarray(points, dtype=np.float64), order=1)
        norm = np.linalg.norm(fg[..., 1:], axis=-1)
        with np.errstate(all="ignore"):
            return fg[..., 0] / norm, fg[..., 1:] / norm[..., None]

    def location_error(self, estimate, truth) -> float | None:
        """``|p - p*|`` up to the surface's declared symmetries (rotations about
        the origin); ``None`` on a surface with continuous symmetries."""
        if self.symmetries is None:
            return None
        estimate = np.asarray(estimate, dtype=float)
        images = rotate(self.symmetries, np.asarray(truth, dtype=float))
        return float(np.min(np.linalg.norm(images - estimate, axis=-1)))

    def wrap(self, uv: np.ndarray) -> np.ndarray:
        """Wrap periodic and clip bounded parameters into the domain."""
        uv = np.array(uv, dtype=np.float64, copy=True)
        uv[..., 0] = self.domain_u.wrap(uv[..., 0])
        uv[..., 1] = self.domain_v.wrap(uv[..., 1])
        return uv

    def inside(self, uv: np.ndarray, tol: float = 1e-12) -> np.ndarray:
        """True where bounded parameters lie within their interval."""
        ok = np.ones(np.shape(uv)[:-1], dtype=bool)
        for i, dom in enumerate((self.domain_u, self.domain_v)):
            if not dom.periodic:
                t = uv[..., i]
                ok &= (t >= dom.lo - tol * dom.length) & (t <= dom.hi + tol * dom.length)
        return ok

    @cached_property
    def _grid(self):
        nu, nv = self.resolution
        uu, vv = np.meshgrid(self.domain_u.grid(nu), self.domain_v.grid(nv), indexing="ij")
        return np.stack([uu.ravel(), vv.ravel()], axis=-1)

    @cached_property
    def size(self) -> float:
        pts = self.evaluate(self._grid[:, 0], self._grid[:, 1])
        pts = pts[np.all(np.isfinite(pts), axis=1)]
        return float(norm3(np.ptp(pts, axis=0)))

    # ------------------------------------------------------------------ table
    def table_samples(self, *, resolution=None, rng=None) -> TableSamples:
        """Principal curvatures on a uniform grid of the domain (Section 4.1).

        ``resolution`` is ``n`` or ``(nu, nv)``; default from the model file.
        Singular grid points (poles of a parametrisation) are left out.
        """
        if resolution is None:
            uv = self._grid
        else:
            nu, nv = (resolution, resolution) if np.isscalar(resolution) else resolution
            uu, vv = np.meshgrid(self.domain_u.grid(int(nu)), self.domain_v.grid(int(nv)), indexing="ij")
            uv = np.stack([uu.ravel(), vv.ravel()], axis=-1)
        k1, k2, n, regular = self.curvatures(uv[:, 0], uv[:, 1])
        pts = self.evaluate(uv[:, 0], uv[:, 1])
        keep = regular & np.all(np.isfinite(pts), axis=1) & np.isfinite(k1) & np.isfinite(k2)
        return TableSamples(uv[keep], pts[keep], n[keep], k1[keep], k2[keep])

    # ------------------------------------------------------------------ sites
    def site_frame(self, site) -> SiteFrame:
        u, v = np.asarray(site, dtype=np.float64)[:2]
        jet = self.frame_jet(np.array(u), np.array(v))
        if not jet.regular:
            raise ValueError(f"the parametrisation is singular at (u, v) = ({u:.6g}, {v:.6g})")
        return SiteFrame(np.array([u, v]), jet.point, jet.frame[:, 0], jet.frame[:, 1], jet.frame[:, 2])

    def locate(self, point, *, start=None) -> np.ndarray:
        """(u, v) of the surface point nearest to ``point``: grid search (or from
        ``start``, a nearby ``(u, v)``), then Gauss-Newton."""
        point = np.asarray(point, dtype=np.float64)
        if start is None:
            nu, nv = 200, 200
            uu, vv = np.meshgrid(self.domain_u.grid(nu), self.domain_v.grid(nv), indexing="ij")
            grid = np.stack([uu.ravel(), vv.ravel()], axis=-1)
            pts = self.evaluate(grid[:, 0], grid[:, 1])
            d2 = np.sum((pts - point) ** 2, axis=1)
            d2[~np.isfinite(d2)] = np.inf
            uv = grid[int(np.argmin(d2))]
        else:
            uv = self.wrap(np.asarray(start, dtype=np.float64)[:2])
        for _ in range(30):
            s, su, sv, *_ = self._derivatives(uv[0], uv[1])
            r = point - s
            a, b, c = dot3(su, su), dot3(su, sv), dot3(sv, sv)            # J^T J for J = [su sv]
            gu, gv = dot3(su, r), dot3(sv, r)
            det = a * c - b * b
            if not det > 0:                                               # a singular point: stay
                break
            step = np.array([(c * gu - b * gv) / det, (a * gv - b * gu) / det])
            uv = self.wrap(uv + step)
            if norm3(step[0] * su + step[1] * sv) < 1e-13 * max(self.size, 1.0):
                break
        return uv

    def random_sites(self, count: int, *, rng=None, margin: float = 0.0) -> np.ndarray:
        """Sites uniform by area: uniform (u, v), kept with probability ~ |su x sv|.

        ``margin`` (a fraction of each bounded interval) keeps sites away from
        the edges of the domain.
        """
        rng = np.random.default_rng(rng)
        probe = self._grid
        _, su, sv, *_ = self._derivatives(probe[:, 0], probe[:, 1])
        area = np.linalg.norm(np.cross(su, sv), axis=1)
        amax = float(np.nanmax(area)) * 1.05
        out = []
        lo = []
        hi = []
        for dom in (self.domain_u, self.domain_v):
            pad = 0.0 if dom.periodic else margin * dom.length
            lo.append(dom.lo + pad)
            hi.append(dom.hi - pad)
        while sum(len(o) for o in out) < count:
            uv = rng.uniform(lo, hi, size=(4 * count + 16, 2))
            _, su, sv, *_ = self._derivatives(uv[:, 0], uv[:, 1])
            a = np.linalg.norm(np.cross(su, sv), axis=1)
            keep = rng.uniform(0, amax, size=len(uv)) < a
            out.append(uv[keep])
        return np.concatenate(out)[:count]

    # ------------------------------------------------------------------ sections
    def plane_section(self, site, tangent, *, spacing: float, count: int) -> np.ndarray:
        return self.plane_sections(site, np.asarray(tangent, dtype=np.float64)[None], spacing=spacing, count=count)[0]

    def plane_sections(self, site, tangents, *, spacing: float, count: int, substeps: int = 4) -> np.ndarray:
        """Several plane sections through one site, traced in the (u, v) domain.

        Each plane contains the normal at the site and one of ``tangents``
        ``(k, 3)``.  The section curve ``(sigma(u, v) - p) . m = 0`` is traced
        in both directions with RK4 on arc length, corrected back onto the
        plane after every step, and resampled at exact arc lengths
        ``(i - (count - 1) / 2) * spacing``.  Returns ``(k, count, 3)``.
        """
        with np.errstate(all="ignore"):
            return trace_sections(self, site, tangents, spacing=spacing, count=count, substeps=substeps)

    # ------------------------------------------------------------------ storage
    def to_store(self) -> dict[str, np.ndarray]:
        """Arrays that rebuild this model in a database (its TOML text, as bytes)."""
        return {"source_text": np.frombuffer(self.text.encode("utf-8"), dtype=np.uint8)}

    @classmethod
    def from_store(cls, arrays, *, name: str, source: str) -> "ClosedFormSurface":
        text = bytes(np.asarray(arrays["source_text"], dtype=np.uint8)).decode("utf-8")
        return cls.from_text(text, source=source, name=name)

    def __repr__(self) -> str:
        return f"ClosedFormSurface(name={self.name!r}, source={self.source!r})"
