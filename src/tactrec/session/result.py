"""What a session's recognition returns: one model's joint pose (:class:`Hypothesis`) and the
result over all models (:class:`SessionResult`); :mod:`tactrec.session` computes them."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..answer import Answer
from ..linalg import rotate
from ..probability import UNKNOWN_PRIOR, Evidence

__all__ = ["Hypothesis", "SessionResult"]


@dataclasses.dataclass(frozen=True)
class Hypothesis:
    """One model's joint pose over a session's touches.

    Attributes
    ----------
    model : str
    rotation, translation : (3, 3), (3,) float
        ``world2model``: ``model = scale * rotation @ world + translation``.
    scale : float
        World (data) units to model units.
    error : float
        Mean distance of the points of the touches it fits to the model, data units.
    per_touch : (N,) float
        Each touch's mean distance under this pose, data units.
    consistent : tuple of bool
        Whether each touch is consistent with the pose (see :mod:`tactrec.session`).
    poses : (p, 3, 4) float or None
        The pose first, then poses along the motions the touches leave free (along a cylinder,
        over a flat patch) that every touch is still consistent with (``[R | t]`` each);
        computed when :meth:`Session.family` is asked (None until then).
    """

    model: str
    rotation: np.ndarray
    translation: np.ndarray
    scale: float
    error: float
    per_touch: np.ndarray
    consistent: tuple
    poses: np.ndarray | None = None

    def to_json(self, probability: float | None = None, contact: np.ndarray | None = None) -> dict:
        """The ranking entry; ``location`` is where the world point ``contact`` (the latest touch's
        contact) lies on the model under this pose."""
        out = {"model": self.model, "error": float(self.error)}
        if contact is not None:
            out["location"] = (self.scale * rotate(self.rotation, contact) + self.translation).tolist()
        out.update(rotation=self.rotation.tolist(), translation=self.translation.tolist(),
                   per_touch_error=[float(e) for e in self.per_touch])
        if self.scale != 1.0:
            out["scale"] = float(self.scale)
        if probability is not None:
            out["probability"] = float(probability)
        if not all(self.consistent):
            out["inconsistent_touches"] = [i for i, c in enumerate(self.consistent) if not c]
        return out


@dataclasses.dataclass(frozen=True)
class SessionResult(Answer):
    """The recognition of a session: one object, one pose per model.

    ``ranking`` holds the models with a joint pose, by error over the touches not slipped;
    ``probabilities`` are theirs (with ``unknown``, the probability that the object is none of
    them, sum 1; :mod:`tactrec.probability`); ``slipped`` the touches no model's pose fits;
    ``estimate`` the latest touch's contact, normal and curvatures in the world frame; ``stages``
    the add's ``seconds`` by part (:data:`tactrec.session.STAGES`: the touch's own search, the
    joint fits, the search with the other touches in the score); ``missed`` the lines that met
    nothing (:meth:`tactrec.session.Session.add_miss`); ``outliers`` how many points each touch set
    aside as off its curve's trace (:mod:`tactrec.outliers`); ``chance`` the database's null model
    of chance fits (:mod:`tactrec.chance`, None where it has none); ``searched`` the work and the
    most work allowed (closest-point queries; None: no limit) of each search the add ran, the
    touch's own first (:mod:`tactrec.session`, step 1), then step 5's.
    """

    ranking: list
    evidence: Evidence | None
    slipped: tuple
    touches: int
    rejected: dict
    seconds: float
    estimate: object = None
    stages: dict = dataclasses.field(default_factory=dict)
    unknown_prior: float = UNKNOWN_PRIOR
    missed: int = 0
    outliers: tuple = ()
    chance: object = None
    searched: tuple = ()

    def _posed(self) -> list[str]:
        return [h.model for h in self.ranking]

    def hypothesis(self, model: str) -> Hypothesis | None:
        return next((h for h in self.ranking if h.model == model), None)

    def to_json(self) -> dict:
        """docs/formats.md's result for a session (``rotation``/``translation`` map the world onto each model)."""
        p = self.probabilities
        g = self.estimate
        ranking = [h.to_json(p.get(h.model), None if g is None else g.contact) for h in self.ranking]
        ranking += [{"model": name, "error": None, "rejected": why} for name, why in self.rejected.items()]
        out = {"best": self.best, "ranking": ranking}
        if g is not None:                                            # the latest touch, world frame
            out.update(contact=g.contact.tolist(), normal=g.normal.tolist(), curvatures=g.reported)
        out.update(confidence=self.confidence, unknown=self.unknown, calibrated=self.chance is not None,
                   ambiguous=self.ambiguous, touches=self.touches,
                   slipped=list(self.slipped), missed=self.missed,
                   outliers=[int(n) for n in self.outliers], seconds=round(self.seconds, 4))
        return out
