"""A session's touches, and what the one fit test measures on them (:mod:`tactrec.session.core`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..probability import FLOOR, fit_limit
from .record import TouchRecord, allowed_fit, fits

__all__ = ["Touches"]


@dataclasses.dataclass(frozen=True)
class Touches:
    """The touches of a session in order, one :class:`~.record.TouchRecord` each, and the method's
    ``floor`` (a fit's mean distance per unit radius on noise-free data) their fit limits read."""

    records: tuple = ()
    floor: float = FLOOR

    def __len__(self) -> int:
        return len(self.records)

    def with_record(self, record: TouchRecord) -> "Touches":
        """These touches and ``record`` after them."""
        return dataclasses.replace(self, records=self.records + (record,))

    @property
    def features(self) -> list:
        """Each touch's :class:`~tactrec.features.Touch` (world frame), in order."""
        return [r.features for r in self.records]

    @property
    def tips(self) -> np.ndarray:
        """Each touch's tip radius ``(N,)``, data units."""
        return np.array([r.tip for r in self.records], dtype=np.float64)

    @property
    def world(self) -> list:
        """Each touch's data in the world frame, in order."""
        return [r.world for r in self.records]

    def contacts(self) -> np.ndarray:
        """Each touch's contact in the world frame ``(N, 3)``: the one its data give, else its estimate's."""
        return np.array([r.world.contact if r.world.contact is not None else r.features.geometry.contact
                         for r in self.records])

    def joined_contacts(self, touches):
        """The single contacts of the touches ``touches`` (indices) of contacts, in that order, as one
        :class:`~tactrec.io.contacts.Contacts` (world frame); None where none of them is one."""
        pooled = None
        for i in touches:
            c = self.records[i].world.contacts
            if c is not None:
                pooled = c if pooled is None else pooled.joined(c)
        return pooled

    def points(self, touches) -> np.ndarray:
        """How many points each of the touches ``touches`` (indices) has: ``(k,)``."""
        return np.array([len(self.records[i].points) for i in touches], dtype=np.float64)

    def pooled(self, values, touches) -> float:
        """The points-weighted mean of per-touch ``values`` (one per index of ``touches``)."""
        sizes = self.points(touches)
        return float((sizes * np.asarray(values, dtype=np.float64)).sum() / sizes.sum())   # element-wise: no BLAS

    def limit(self, touches) -> float:
        """The points-weighted mean of the :func:`~tactrec.probability.fit_limit` of the touches
        ``touches`` (indices)."""
        return self.pooled([fit_limit(self.records[i].features, self.floor) for i in touches], touches)

    def fitted_at(self, error: float, touches) -> bool:
        """Whether a pose whose points-weighted mean distance over the touches ``touches`` (indices)
        is ``error`` (data units) fits them as well as their noise allows (the points-weighted mean
        of their fit limits, by the one fit test :func:`~.record.fits`): then no search can fit
        them better."""
        return bool(fits(error, self.limit(touches), self.points(touches).sum()))

    def reference(self, model: str | None = None) -> np.ndarray:
        """Per touch ``(N,)``, data units: the fit its own search reached on ``model`` (None: on its
        best model), or its fit limit, whichever is larger: what the fit test measures it against."""
        return np.array([max(r.own_error(model), fit_limit(r.features, self.floor)) for r in self.records])

    def limits(self) -> np.ndarray:
        """Per touch ``(N,)``, data units: the largest mean distance of a fit as good as its own search
        found on any model (:func:`~.record.allowed_fit` of :meth:`reference`)."""
        return allowed_fit(self.reference(), self.points(range(len(self.records))))

    def consistent(self, name: str, per_touch: np.ndarray) -> np.ndarray:
        """Which touches are consistent (:mod:`.core`, step 3) with poses of model ``name`` whose
        per-touch mean distances (data units) are ``per_touch (h, N)``: ``(h, N)`` bool, by the one
        fit test against each touch's own fit on the model."""
        return fits(per_touch, self.reference(name)[None], self.points(range(len(self.records)))[None])
