"""Fast registration onto a closed-form surface (method ``fast``).

Differences from the paper's Section 4.2 (:mod:`.closedform_paper`):

1. the ``candidates`` table rows nearest in curvature are taken, whatever
   their distance, instead of those within a hard ``delta``: a noisy
   estimate no longer loses the true location;
2. the initial rotation about the normal is the paper's (scan and bisection
   on eq. 11), but then, instead of steepest descent on ``(u, v, phi)``, the
   pose is refined in all six degrees of freedom by damped Gauss-Newton on
   the first-order distances ``f / |grad f|`` of eq. 11 (point-to-plane
   against the implicit surface: :mod:`.solver`), all candidates at once; the contact point
   is then the surface point nearest to the moved contact.

The error is eq. 12's mean first-order distance, as in the paper.

With a round tip (:mod:`tactrec.tip`) the rows and the first turn come from the
data moved onto the surface (``surface``) and the corrected estimate, and the
steps and the error from the centres against the offset surface (``exact``).
"""

from __future__ import annotations

import numpy as np

from ..estimation import LocalGeometry
from ..linalg import compose, norm3, rotate, times
from ..surfaces.closedform import ClosedFormSurface
from ..tables import CurvatureTable
from .closedform_paper import Superposition
from .result import Registration, local_frame, rotations_z
from .solver import Criteria, solve

__all__ = ["register", "polish", "refine", "DEFAULTS"]

DEFAULTS = {
    "candidates": 12,       # table rows nearest in curvature
    "phi_samples": 36,
    "bisections": 8,
    "iterations": 12,       # Gauss-Newton steps, every candidate
}


def refine(model: ClosedFormSurface, R: np.ndarray, t: np.ndarray, x: np.ndarray, *, iterations: int
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses ``R (h, 3, 3), t (h, 3)`` of data ``x (m, 3)`` refined by ``iterations`` steps of the one
    point-to-plane solver on the first-order distances ``f / |grad f|`` (:meth:`ClosedFormSurface.planes`,
    eq. 11).  Returns the poses and their errors (eq. 11, ``inf`` where ``f`` is singular)."""
    fit = solve(model, R, t, x, Criteria(iterations, tolerance=0.0))
    return fit.R, fit.t, fit.error


def _result(model, geometry, R, t, error, start, candidates) -> Registration | None:
    """The registration, or ``None`` if the contact has left the declared patch (the implicit
    surface of eq. 11 goes on beyond it)."""
    p = rotate(R, geometry.contact) + t
    uv = model.locate(p, start=start)
    jet = model.frame_jet(uv[0:1], uv[1:2])
    if not norm3(jet.point[0] - p) <= 3.0 * error + 1e-9 * model.size:
        return None
    return Registration(model=model.name, error=float(error), location=jet.point[0], rotation=R, translation=t,
                        candidates=candidates, site=uv, phi=None)


def register(model: ClosedFormSurface, table: CurvatureTable, geometry: LocalGeometry, points: np.ndarray, *,
             candidates: int = DEFAULTS["candidates"], phi_samples: int = DEFAULTS["phi_samples"],
             bisections: int = DEFAULTS["bisections"], iterations: int = DEFAULTS["iterations"],
             exact=None, surface: np.ndarray | None = None, **_ignored) -> Registration:
    """Register data ``points (m, 3)`` onto ``model`` from the rows nearest in curvature.  ``exact``:
    what the steps measure the points against (default ``model``; the offset surface for a tip's
    centres), ``surface``: the points moved onto the surface (default ``points``), which pose the
    first turn."""
    idx, _ = table.nearest(geometry.k1, geometry.k2, candidates)
    if len(idx) == 0:
        return Registration.unfitted(model.name, "empty table")
    x = np.asarray(points, dtype=np.float64)
    on = x if surface is None else np.asarray(surface, dtype=np.float64)
    if np.max(np.linalg.norm(on - geometry.contact, axis=1)) > model.size:
        return Registration.unfitted(model.name, "the touch is larger than the model")
    L = local_frame(geometry.normal, geometry.directions[0])
    problem = Superposition(model, times(on - geometry.contact, L.T))
    uv0 = table.samples.sites[idx]
    phi0, E0 = problem.initial_phi(uv0, samples=phi_samples, bisections=bisections)
    jet = model.frame_jet(uv0[:, 0], uv0[:, 1])
    usable = np.isfinite(E0) & np.all(np.isfinite(jet.frame), axis=(1, 2))
    if not usable.any():
        return Registration.unfitted(model.name, "registration failed")
    uv0, phi0 = uv0[usable], phi0[usable]
    R = compose(compose(jet.frame[usable], rotations_z(phi0)), L)
    t = jet.point[usable] - np.einsum("hij,j->hi", R, geometry.contact)
    R, t, error = refine(model if exact is None else exact, R, t, x, iterations=iterations)
    for b in np.argsort(error)[:5]:
        if not np.isfinite(error[b]):
            break
        found = _result(model, geometry, R[b], t[b], error[b], uv0[b], len(idx))
        if found is not None:
            return found
    return Registration.unfitted(model.name, "registration failed")


def polish(model: ClosedFormSurface, registration: Registration, geometry: LocalGeometry, points: np.ndarray, *,
           iterations: int = 20, exact=None, **_ignored) -> Registration:
    """Continue the Gauss-Newton refinement of ``registration`` (``exact`` as for :func:`register`)."""
    R, t, error = refine(model if exact is None else exact, registration.rotation[None], registration.translation[None],
                         np.asarray(points, dtype=np.float64), iterations=iterations)
    if not error[0] < registration.error:
        return registration
    found = _result(model, geometry, R[0], t[0], error[0], registration.site, registration.candidates)
    return registration if found is None else found
