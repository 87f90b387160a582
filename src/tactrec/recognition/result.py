"""What a recognition returns (:class:`Recognition`): the ranking, the estimate, the probabilities."""

from __future__ import annotations

import dataclasses
import functools

from ..estimation import LocalGeometry
from ..features import Touch
from ..io.meeting import meeting
from ..answer import Answer
from ..probability import AMBIGUOUS, UNKNOWN_PRIOR, Evidence
from ..registration.result import Registration

__all__ = ["Recognition", "LOCATED"]

#: the data leave the contact free when its spread (the root of the trace of its covariance under the
#: fit) exceeds this many times the fit's mean residual: the dilution of precision of a direction
#: the data do not constrain (on YCB scans, the median is 3 for P3 touches and 6 for hard ones)
LOCATED = 10.0


@dataclasses.dataclass(frozen=True)
class Recognition(Answer):
    """Outcome of recognising one touch against a set of models: the ranking, and the answer read
    off its probabilities (:class:`~tactrec.answer.Answer`: ``best``, ``probabilities``,
    ``unknown``, ``confidence``, ``ambiguous``).

    Attributes
    ----------
    ranking : list of Registration
        Sorted by error (data units), rejected models last.
    estimate : LocalGeometry
        Contact, normal and principal curvatures estimated from the data.
    seconds : float
        Wall time of the recognition, its probabilities included.
    method : str
    evidence : Evidence or None
        What the probabilities come from (:mod:`tactrec.probability`): each data point's distance
        to each accepted model under its pose.
    settled : bool
        False when the method's search ended on its budget rather than by its own rule.
    work : int
        The method's work (``fast``: closest-point queries).
    depth : int
        How many steps of its schedule the method's search ran.
    touch : Touch or None
        The touch as recognition saw it (points, estimate, noise), for callers that go on with it.
    allowed : int or None
        The most work the search's schedule could spend (``fast``: its budget, its grids about a
        stall up to as much again; None for a method without one).
    unknown_prior : float
        The prior probability that the touch came from none of the models (:mod:`tactrec.probability`).
    chance : NullModel or None
        The database's null model of chance fits (:mod:`tactrec.chance`), None where it has none:
        then ``unknown`` comes from the fit test alone.
    place : float
        The answer's place's share of the replicates among it and the other places of its model
        the search posed beyond the touch's reach (:mod:`.places`): below
        :data:`~tactrec.probability.AMBIGUOUS`, the data fit another place of the object about as
        well, and the contact is not located; 1 where no other place was posed.
    """

    ranking: list[Registration]
    estimate: LocalGeometry
    seconds: float
    method: str
    evidence: Evidence | None = None
    settled: bool = True
    work: int = 0
    depth: int = 1
    touch: Touch | None = None
    allowed: int | None = None
    unknown_prior: float = UNKNOWN_PRIOR
    chance: object = None
    place: float = 1.0

    def _posed(self) -> list[str]:
        return [r.model for r in self.ranking if r.ok]

    @property
    def located(self) -> bool:
        """False when the data leave the contact free on the best model: its ``spread`` exceeds
        :data:`LOCATED` x its error (a direction the data do not constrain, along a cylinder or
        over a flat patch), or another place of it fits about as well (:attr:`place` below
        :data:`~tactrec.probability.AMBIGUOUS`)."""
        r = self.registration
        return r is None or not (r.spread > LOCATED * r.error or self.place < AMBIGUOUS)

    @property
    def outliers(self) -> int:
        """How many of the touch's points were set aside (:mod:`tactrec.outliers`; 0 without a touch)."""
        return int(self.touch.outliers) if self.touch is not None else 0

    @functools.cached_property
    def meeting(self) -> float:
        """How far the curves pass from their meeting point: the largest distance of a curve (of the
        points kept) from it, data units (0 without a touch; :func:`tactrec.io.meeting.meeting`)."""
        if self.touch is None or self.touch.data.contacts is not None:
            return 0.0
        return float(meeting(self.touch.data)[1].max())

    @property
    def registration(self) -> Registration | None:
        """The best model's registration (None when every model was rejected)."""
        return next((r for r in self.ranking if r.model == self.best and r.ok), None)

    def to_json(self) -> dict:
        """The result of docs/formats.md (``tactrec recognize --json``)."""
        return {
            "best": self.best,
            "ranking": [dict(r.to_json(), probability=self.probabilities[r.model]) if r.ok else r.to_json()
                        for r in self.ranking],
            "contact": self.estimate.contact.tolist(),
            "normal": (self.estimate.normal * (self.registration.normal_sign if self.registration else 1)).tolist(),
            "curvatures": self.estimate.reported,
            "method": self.method,
            "confidence": self.confidence,
            "unknown": self.unknown,
            "calibrated": self.chance is not None,
            "ambiguous": self.ambiguous,
            "located": self.located,
            "place": self.place,
            "settled": self.settled,
            "outliers": self.outliers,
            "meeting": self.meeting,
            "seconds": round(self.seconds, 4),
        }
