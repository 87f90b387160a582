"""One record per touch of a session, and the one fit test every step of a session applies."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..probability import CONSISTENT_SE, fit_standard_error

__all__ = ["TouchRecord", "CONSISTENT_SE", "allowed_fit", "fits"]


def allowed_fit(fit, points):
    """The largest mean distance as good as a fit of ``fit`` over ``points`` points: within
    :data:`CONSISTENT_SE` of its standard errors (:func:`tactrec.probability.fit_standard_error`,
    which is proportional to the fit); element-wise over arrays."""
    return np.asarray(fit, dtype=np.float64) * (1.0 + CONSISTENT_SE * fit_standard_error(1.0, points))


def fits(error, fit, points):
    """The session's one fit test: whether a mean distance ``error`` over ``points`` points is as good
    as a fit of ``fit`` (:func:`allowed_fit`); element-wise over arrays."""
    return np.asarray(error) <= allowed_fit(fit, points)


@dataclasses.dataclass(frozen=True)
class TouchRecord:
    """One touch of a session: as given (``given``, :class:`~tactrec.io.session.SessionTouch`), in the
    world frame (``world``, :class:`~tactrec.io.touch.TactileData`), its own recognition there
    (``own``, :class:`~tactrec.recognition.Recognition`) and what recognition needs of it
    (``features``, :class:`~tactrec.features.Touch`, world frame)."""

    given: object
    world: object
    own: object

    @property
    def features(self):
        return self.own.touch

    @property
    def points(self) -> np.ndarray:
        """The touch's points ``(m, 3)``, world frame."""
        return self.own.touch.points

    @property
    def tip(self) -> float:
        """The touch's tip radius, data units (0: points on the surface; :mod:`tactrec.tip`)."""
        return self.own.touch.tip

    @property
    def surface_curves(self) -> tuple:
        """The touch's curves moved onto the surface on the side of its own normal (:mod:`tactrec.tip`;
        the curves themselves without a tip), world frame."""
        features = self.own.touch
        return features.on_surface(features.sides[0][0]).data.curves

    def own_error(self, model: str | None = None) -> float:
        """The touch's own search's error (data units) on ``model`` (None: on its best model); 0 where
        that search registered none."""
        errors = [r.error / r.scale for r in self.own.ranking if r.ok and (model is None or r.model == model)]
        return min(errors, default=0.0)
