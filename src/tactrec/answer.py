"""What a single touch's recognition and a session's result share: the answer and how sure it is.

:class:`Answer` turns a result's evidence (:class:`~tactrec.probability.Evidence`) into each model's
probability and ``unknown``'s, and reads the answer off them by one rule for both kinds of result
(:func:`~tactrec.probability.most_probable`): the most probable of the models with a pose, the
lowest error of equals.
"""

from __future__ import annotations

import functools

from .probability import AMBIGUOUS, most_probable

__all__ = ["Answer"]


class Answer:
    """The answer of a result (a base of :class:`~tactrec.recognition.Recognition` and
    :class:`~tactrec.session.SessionResult`): the subclass has ``evidence`` (None: no model has a
    pose), ``unknown_prior`` and ``chance`` (the null model of chance fits, or None), and names its
    models with a pose, by error, in :meth:`_posed`."""

    def _posed(self) -> list[str]:
        raise NotImplementedError

    @functools.cached_property
    def _outcomes(self) -> tuple[dict[str, float], float]:
        if self.evidence is None:
            return {}, 1.0
        return self.evidence.named_outcomes(prior=self.unknown_prior, chance=self.chance)

    @property
    def probabilities(self) -> dict[str, float]:
        """Each model's probability that the data came from it (with :attr:`unknown`, sum 1;
        :mod:`tactrec.probability`)."""
        return self._outcomes[0]

    @property
    def unknown(self) -> float:
        """The probability that the data came from none of the models (docs/formats.md)."""
        return self._outcomes[1]

    @functools.cached_property
    def best(self) -> str | None:
        """The answer (docs/formats.md): the most probable of the models with a pose, the lowest error
        of equals (:func:`~tactrec.probability.most_probable`); None where none has one."""
        return most_probable(self._posed(), self.probabilities)

    @property
    def confidence(self) -> float:
        """The best model's probability (0 where there is none)."""
        return float(self.probabilities.get(self.best, 0.0)) if self.best is not None else 0.0

    @property
    def ambiguous(self) -> bool:
        """True exactly when :attr:`confidence` is below :data:`~tactrec.probability.AMBIGUOUS`
        (docs/formats.md); False where there is no answer."""
        return self.best is not None and bool(self.confidence < AMBIGUOUS)
