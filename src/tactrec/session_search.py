"""Steps 1 and 5 of a session (:mod:`tactrec.session`): which searches an added touch gets, in what order.

A touch added to a session whose touches are kept is first scored under the
session's poses so far (a joint fit from them alone, no search: a fraction
of a search's cost).

- When the best model's pose is then consistent with every touch kept, the
  touch is searched on its own (step 1), so that every other model gets its
  poses too and the probabilities weigh each model at its best, and step 5
  runs only if that search hands the lead to a pose that does not fit them
  all.
- When it is not, the touch is searched first with the other touches' points
  in the score (:meth:`tactrec.recognition.Recognizer.recognize` with
  ``context``), over every model whose pose does not fit them all.  A touch
  searched alone ranks its places by its own curvatures, and on a short noisy
  touch the true place can rank beyond the budget: the search then runs its
  whole budget and finds nothing.  The search with the context ranks the
  same places but scores each pose on every touch and stops once one fits
  them all.  When it finds one, the touch is never searched alone.  When it
  does not, the touch is
  searched alone, and then the touch kept before it is searched with the
  others as its context (:data:`STARTS`).

Until it is searched alone (if ever), the touch's own fit, which its
allowance in the slip test (step 3) and the searches' stopping fit build on,
stands in at its :func:`tactrec.probability.fit_limit` (what its noise allows
a perfect fit) times how far above theirs the touches searched alone fitted
(the median ratio; :meth:`tactrec.session.Session._own_fits`): a scan's
facets keep the true pose's fit above the noise's, alike for every touch of
the object.  A search alone's poses then change which touches a cached fit
counts as consistent (a model's allowance for the touch becomes its own fit
on that model): the cached fits are reassessed when it arrives.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .probability import fit_limit

__all__ = ["explained", "run", "search_alone", "unexplained", "STARTS"]

#: step 5 searches from this many touches, newest first: the new one and the one kept before it, so a
#: touch may be searched with the others in its score when it is added and again when the next one is
STARTS = 2


def run(session, slipped: set) -> None:
    """Steps 1 and 5 for the touch just added to ``session``, which keeps earlier touches (all but
    those ``slipped`` before this one); for a method that scores a context."""
    session.result = session._joint_fit()
    searched = 0
    if not explained(session, slipped):
        _with_context(session, len(session.features) - 1, slipped)
        searched = 1
        if explained(session, slipped):
            return
    search_alone(session)
    use = [i for i in range(len(session.features)) if i not in slipped]
    for start in use[::-1][searched:STARTS]:
        if explained(session, slipped) or not unexplained(session, slipped):
            return
        _with_context(session, start, slipped)


def search_alone(session) -> None:
    """Step 1: the newest touch's own search, its poses fitted jointly (steps 2-4); the cached fits'
    consistency flags are reassessed under the allowance it gives the touch (module text)."""
    rec = session._timed("own", session.recognizer.recognize, session.world[-1])
    session.solo[-1] = rec
    session.searches.append(rec)
    for done in session._fits.values():
        for name, h in done.items():
            flags = session.consistent(name, np.asarray(h.per_touch)[None])[0]
            done[name] = dataclasses.replace(h, consistent=tuple(bool(c) for c in flags))
    session.result = session._joint_fit(rec)


def _with_context(session, start: int, slipped: set) -> None:
    """Search touch ``start`` again with the other touches kept in its score, over the models
    :func:`unexplained` names, stopping once a pose fits the touches as well as their own searches
    fit each (the points-weighted mean of :meth:`~tactrec.session.Session._own_fits`)."""
    use = [i for i in range(len(session.features)) if i not in slipped]
    fit = session.pooled(session._own_fits()[use], use)
    context = [c for i in use if i != start for c in session.world[i].curves]
    found = session._timed("context", session.recognizer.recognize, session.world[start], context=context,
                           among=unexplained(session, slipped), fit=fit)
    session.searches.append(found)
    session.result = session._joint_fit(found)


def explained(session, slipped: set) -> bool:
    """Whether the best model's joint pose is consistent with every touch but those ``slipped``
    before this one, the new touch included even if step 4 calls it slipped: a touch is only left
    out as slipped once a search scoring its poses on every touch has found none that fits them all."""
    result = session.result
    best = result.hypothesis(result.best) if result.best else None
    return best is not None and all(c for i, c in enumerate(best.consistent) if i not in slipped)


def unexplained(session, slipped: set) -> list[str]:
    """The models a search with a context covers: those whose joint pose is not consistent with
    every touch but those ``slipped`` before (or that have none), and that the new touch fits on its
    own (its own search's error within :meth:`~tactrec.session.Session._limits`).

    When the new touch has no search alone yet, or that search fitted no model (its best error
    beyond what the touch's noise allows, :func:`fit_limit` and three standard errors), its errors
    rule nothing out: every model whose joint pose fails some touch is covered."""
    def fails(name):
        h = session.result.hypothesis(name)
        return h is None or not all(c for i, c in enumerate(h.consistent) if i not in slipped)

    own = session.solo[-1]
    f = session.features[-1]
    if own is None or session._own_fits()[-1] > session.allowed(fit_limit(f, session._floor), [-1]):
        return [e.name for e in session.recognizer.models if fails(e.name)
                and not _rejected_unsearched(own, e.name)]
    limit = session._limits()[-1]
    out = []
    for r in own.ranking:
        error = r.error / r.scale if r.ok else (np.inf if str(r.rejected).startswith("deferred") else None)
        if error is not None and error <= limit and fails(r.model):
            out.append(r.model)
    return out


def _rejected_unsearched(own, name: str) -> bool:
    """Whether the search alone ``own`` rejected model ``name`` for a reason other than its error
    (a touch larger than the patch, say): no search can fit it then."""
    if own is None:
        return False
    r = next((r for r in own.ranking if r.model == name), None)
    return r is not None and not r.ok and not str(r.rejected).startswith("deferred")
