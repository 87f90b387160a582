"""Recognition: register the touch on every model, rank by error (Section 3.3).

For each model: convert the data to the model's units, look up candidates by
the estimated principal curvatures (a model with none is rejected, "NC"),
register from them and keep the registration error ``E(M)``; the model with
the smallest error is recognised (eq. 9).  When the touch carries no
``outward`` hint, both orientations of the data normal are tried.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Iterable

import numpy as np

from .estimation import LocalGeometry, estimate, noise_level
from .io.touch import TactileData
from .registration import (DEFAULT_METHOD, Registration, get_polisher, get_promise, get_registrar, get_rescuer,
                           get_widener)
from .tables import CurvatureTable
from .units import conversion

__all__ = ["Recognition", "recognize", "register_on_model", "ModelEntry"]


@dataclasses.dataclass(frozen=True)
class ModelEntry:
    """A model with its lookup table, ready for recognition."""

    model: object
    table: CurvatureTable

    @property
    def name(self) -> str:
        return self.model.name


@dataclasses.dataclass(frozen=True)
class Recognition:
    """Outcome of recognising one touch against a set of models.

    Attributes
    ----------
    best : str or None
        Name of the recognised model (``None`` if every model was rejected).
    ranking : list of Registration
        Sorted by error, rejected models last.
    estimate : LocalGeometry
        Contact, normal and principal curvatures estimated from the data.
    seconds : float
        Wall time of the recognition.
    method : str
    margin : float
        How much better than the runner-up the best model must fit to be
        told apart from it, data units: ``max(2 sigma / sqrt(m), 0.1 E1)``,
        ``sigma`` the data's noise (per coordinate, from third differences
        along the curves), ``m`` the number of data points, ``E1`` the best
        error.
    """

    best: str | None
    ranking: list[Registration]
    estimate: LocalGeometry
    seconds: float
    method: str
    margin: float = 0.0

    @property
    def ambiguous(self) -> bool:
        """True when the runner-up's error is within :attr:`margin` of the best's: the touch
        fits both models about equally well, and the ranking between them is not to be trusted."""
        ok = [r for r in self.ranking if r.ok]
        if len(ok) < 2:
            return False
        return bool(ok[1].error / ok[1].scale - ok[0].error / ok[0].scale <= self.margin)

    @property
    def registration(self) -> Registration | None:
        return self.ranking[0] if self.ranking and self.ranking[0].ok else None

    def to_json(self) -> dict:
        """The result of INTERFACE.md (``tactrec recognize --json``)."""
        return {
            "best": self.best,
            "ranking": [r.to_json() for r in self.ranking],
            "contact": self.estimate.contact.tolist(),
            "normal": (self.estimate.normal * (self.registration.normal_sign if self.registration else 1)).tolist(),
            "curvatures": [self.estimate.k1, self.estimate.k2],
            "method": self.method,
            "ambiguous": self.ambiguous,
            "margin": self.margin,
            "seconds": round(self.seconds, 4),
        }


def _scaled(geom: LocalGeometry, scale: float) -> LocalGeometry:
    if scale == 1.0:
        return geom
    return dataclasses.replace(geom, contact=geom.contact * scale, k1=geom.k1 / scale, k2=geom.k2 / scale,
                               normal_curvatures=geom.normal_curvatures / scale)


def register_on_model(entry: ModelEntry, data: TactileData, geom: LocalGeometry, *,
                      method: str = DEFAULT_METHOD, bound: float = np.inf, **options) -> Registration:
    """Register one touch on one model, trying both normals if not oriented.

    ``bound`` is the best error found so far on other models, in the data's units."""
    return _on_model(get_registrar(method, entry.model.kind), entry, data, geom, bound=bound, **options)


def _on_model(register, entry: ModelEntry, data: TactileData, geom: LocalGeometry, *, bound: float,
              **options) -> Registration:
    """``register`` (a registrar or a rescuer) in the model's units, on both normals if not oriented."""
    model = entry.model
    scale = conversion(data.units, getattr(model, "units", None))
    points = data.points * scale
    curves = [c * scale for c in data.curves]
    orientations = [(1, geom)] if geom.oriented else [(1, geom), (-1, geom.flipped())]
    results = []
    for sign, g in orientations:
        r = register(model, entry.table, _scaled(g, scale), points, curves=curves, bound=bound * scale, **options)
        results.append(dataclasses.replace(r, normal_sign=sign, scale=scale))
    ok = [r for r in results if r.ok]
    if not ok:
        nearest = min(results, key=lambda r: r.cheap)
        return Registration.rejection(model.name, nearest.rejected, scale=scale, cheap=nearest.cheap)
    best = min(ok, key=lambda r: r.error)
    total = sum(r.candidates for r in results)
    return dataclasses.replace(best, candidates=total)


#: models are dealt into this many shares, each registered in order with its own bound
SHARES = 2


def default_workers() -> int:
    """Worker processes for a recognition: two where the machine has them."""
    return max(1, min(2, os.cpu_count() or 1))


def _rank_key(r: Registration):
    """Accepted models first, by error in the data's units (models may differ in units)."""
    return (not r.ok, r.error / r.scale if r.ok else 0.0, r.model)


def _polished(ranking: list[Registration], models: list[ModelEntry], data: TactileData, geom: LocalGeometry,
              method: str, count: int) -> list[Registration]:
    """``ranking`` with its best ``count`` registrations refined further by ``method``'s polisher."""
    by_name = {entry.name: entry for entry in models}
    out = list(ranking)
    for i, r in enumerate(ranking[:count]):
        entry = by_name.get(r.model)
        polisher = get_polisher(method, entry.model.kind) if entry is not None and r.ok else None
        if polisher is None:
            continue
        g = _scaled(geom if r.normal_sign == 1 else geom.flipped(), r.scale)
        better = polisher(entry.model, r, g, data.points * r.scale)
        out[i] = dataclasses.replace(better, normal_sign=r.normal_sign, scale=r.scale)
    return out


def _widened(ranking: list[Registration], models: list[ModelEntry], pool, data: TactileData,
             geom: LocalGeometry, method: str, noise: float, options: dict) -> list[Registration]:
    """``ranking`` after the method's widened search on its best-ranked models, if the method has
    one and its scope (decided from the ranked errors) is not empty.

    Before that, the models the first search pruned with a cheap score the method's ``revisit``
    accepts are registered again without the bound (with ``options``), and the scope decided
    again: a model pruned against the best error so far may yet come within the widened
    search's reach once refined."""
    ok = [r for r in ranking if r.ok]
    by_name = {entry.name: i for i, entry in enumerate(models)}
    widener = get_widener(method, models[by_name[ok[0].model]].model.kind) if ok else None
    if widener is None:
        return ranking
    scope, _, revisit = widener

    def count(ranked):
        return scope(np.array([r.error / r.scale for r in ranked if r.ok]), geom, data.points, noise=noise)

    if not count(ranking):
        return ranking
    best = _best_error(ranking)
    again = [by_name[r.model] for r in ranking
             if not r.ok and np.isfinite(r.cheap) and revisit(r.cheap / r.scale, best)]
    if again:
        ranking = _searched_again(ranking, models, _dealt(again), pool, _unbounded, data, geom, method, options)
    chosen = [by_name[r.model] for r in ranking[:count(ranking)] if r.ok]
    if not chosen:
        return ranking
    return _searched_again(ranking, models, _dealt(chosen), pool, _search_again, data, geom, method, get_widener,
                           _best_error(ranking))


def _dealt(indices: list[int]) -> list[list[int]]:
    """``indices`` dealt into :data:`SHARES` shares (every ``SHARES``-th), in order."""
    return [indices[k::SHARES] for k in range(SHARES)]


def _best_error(ranking: list[Registration]) -> float:
    """The best error of ``ranking`` in the data's units (inf if no model was accepted)."""
    return ranking[0].error / ranking[0].scale if ranking and ranking[0].ok else np.inf


def _rescued(ranking: list[Registration], models: list[ModelEntry], shares, pool, data: TactileData,
             geom: LocalGeometry, method: str, best: float) -> list[Registration]:
    """``ranking`` after the method's wider search on every model, if the method has one and the
    first search's best error ``best`` (data units) says no model fits (the rescuer decides; it
    costs nothing when the best fits).

    Decided on the first search's best, not the widened one's: the widened search looks at
    the few best-ranked models only, so a fit it finds there does not show that the true
    model, ranked lower, would not fit better after the wider search."""
    rescuers = [get_rescuer(method, entry.model.kind) for entry in models]
    if not any(r is not None and r[0](best, geom, data.points) for r in rescuers):
        return ranking
    return _searched_again(ranking, models, shares, pool, _search_again, data, geom, method, get_rescuer, best)


def _searched_again(ranking, models, shares, pool, stage, *args) -> list[Registration]:
    """``ranking`` with the models in ``shares`` searched again by ``stage(part, *args)``
    (:func:`_search_again` or :func:`_unbounded`), each kept where it fits better than before."""
    found = _over_shares(pool, shares, models, stage, *args)
    again = {models[i].name: r for i, r in zip([i for share in shares for i in share], found)
             if r is not None and r.ok}
    out = [again[r.model] if r.model in again and (not r.ok or _rank_key(again[r.model]) < _rank_key(r)) else r
           for r in ranking]
    out.sort(key=_rank_key)
    return out


def _share(part, data, geom, method, options) -> list[Registration]:
    """Register on the models of one share in order, each bounded by the best error before it."""
    out, bound = [], np.inf          # the best error so far in this share, in the data's units
    for entry in part:
        r = register_on_model(entry, data, geom, method=method, bound=bound, **options)
        out.append(r)
        if r.ok:
            bound = min(bound, r.error / r.scale)
    return out


def _unbounded(part, data, geom, method, options) -> list[Registration]:
    """Register on the models of one share without a bound."""
    return [register_on_model(entry, data, geom, method=method, **options) for entry in part]


#: the worker processes and the models they were forked with (held, so their ids stay unique)
_POOL: dict = {}


def _in_worker(stage, indices, *args) -> list:
    """``stage`` on the models at ``indices``, in a worker process: the models it was forked with."""
    models = _POOL["models"]
    return stage([models[i] for i in indices], *args)


def _search_again(part, data, geom, method, lookup, bound) -> list[Registration | None]:
    """The search ``lookup(method, kind)`` gives (a ``(when, search)`` pair) on each model of
    ``part`` (``None`` where there is none)."""
    out = []
    for entry in part:
        found = lookup(method, entry.model.kind)
        out.append(None if found is None else _on_model(found[1], entry, data, geom, bound=bound))
    return out


def _promise(entry: ModelEntry, data: TactileData, geom: LocalGeometry, method: str) -> float:
    """The method's promise of the model for this touch (lower first; inf without one)."""
    promise = get_promise(method, entry.model.kind)
    if promise is None:
        return np.inf
    scale = conversion(data.units, getattr(entry.model, "units", None))
    orientations = [geom] if geom.oriented else [geom, geom.flipped()]
    return min(promise(entry.model, _scaled(g, scale), data.points * scale) for g in orientations)


def _over_shares(pool, shares, models, stage, *args) -> list:
    """``stage(part, *args)`` on each share's models, results in share order: in the worker
    processes, or in this process without a pool or if the pool broke."""
    if pool is not None:
        try:
            futures = [pool.submit(_in_worker, stage, share, *args) for share in shares]
            return [r for future in futures for r in future.result()]
        except BrokenProcessPool:              # a worker died (e.g. out of memory): go on without
            _POOL.clear()
    return [r for share in shares for r in stage([models[i] for i in share], *args)]


def _workers(models: list[ModelEntry], workers: int) -> ProcessPoolExecutor | None:
    """Worker processes forked with ``models``, kept for the next recognition against the same
    models; ``None`` where processes cannot be forked (then the shares run one after the other).

    Processes, not threads: the exact closest-point queries hold Python's global lock."""
    workers = min(int(workers), SHARES)
    key = (tuple(id(e) for e in models), workers)
    if _POOL.get("key") == key:
        return _POOL["pool"]
    if _POOL.get("pool") is not None:
        _POOL["pool"].shutdown()
    _POOL.clear()
    # not from inside another process's worker (daemonic or a benchmark's pool running touches in
    # parallel): forking there can deadlock, and that pool already uses the cores
    nested = multiprocessing.parent_process() is not None
    if workers < 2 or nested or "fork" not in multiprocessing.get_all_start_methods():
        return None
    pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"))
    _POOL.update(key=key, models=models, pool=pool)
    return pool


def recognize(data: TactileData, models: Iterable[ModelEntry], *, method: str = DEFAULT_METHOD,
              window: int | str | None = "auto", degree: int = 3, curvature_method: str = "auto",
              polish: int = 3, workers: int | None = None, **options) -> Recognition:
    """Recognise a touch against ``models`` (Section 3.3).

    Parameters
    ----------
    data : TactileData
    models : iterable of ModelEntry
        Models with their lookup tables (see :mod:`tactrec.database`).
    method : str
        Registration method: ``"fast"`` (the default) or ``"paper"``.
    window, degree, curvature_method
        Passed to :func:`tactrec.estimation.estimate`.
    polish : int
        How many of the best models get the method's final refinement (if it
        has one: ``fast``).  Then, if the best fits only loosely and others
        nearly as well, the models pruned near the best are registered again
        without the bound (``fast``: :func:`tactrec.registration.mesh_fast.revisit`),
        and the few that fit about as well as the best get the method's
        widened search (``fast``: :func:`tactrec.registration.mesh_fast.widen`); if even the first
        search's best does not fit, all models within reach get the widened
        search and then every model its wider search (``fast``:
        :func:`tactrec.registration.mesh_fast.rescue`).
    workers : int, optional
        Processes registering models in parallel (default: up to two, the
        cores of a small machine; forked once and kept for later touches
        against the same models).  The models are ordered by the method's
        promise for the touch (``fast``: the best curvature match), then
        dealt into :data:`SHARES` fixed shares, so the result depends
        neither on this nor on scheduling.
    **options
        Passed to the registration (e.g. ``delta``).  Each model after the
        first of its share also gets ``bound``, the best error so far in the
        share, which ``fast`` uses to skip hopeless models early.
    """
    start = time.perf_counter()
    workers = default_workers() if workers is None else int(workers)
    geom = estimate(data, window=window, degree=degree, method=curvature_method)
    models = list(models)

    # the most promising models first, dealt into fixed shares (every SHARES-th), each with its own
    # bound: the same result whatever the number of workers and however they are scheduled
    order = sorted(range(len(models)), key=lambda i: (_promise(models[i], data, geom, method), i))
    shares = _dealt(order)
    pool = _workers(models, workers)
    ranking = _over_shares(pool, shares, models, _share, data, geom, method, options)
    ranking.sort(key=_rank_key)
    ranking = _polished(ranking, models, data, geom, method, polish)
    ranking.sort(key=_rank_key)
    sigma = float(np.median([noise_level(np.asarray(c, dtype=np.float64)) for c in data.curves]))
    first = _best_error(ranking)
    ranking = _widened(ranking, models, pool, data, geom, method, sigma, options)
    ranking = _rescued(ranking, models, shares, pool, data, geom, method, first)
    best = ranking[0].model if ranking and ranking[0].ok else None
    e1 = _best_error(ranking) if best is not None else 0.0
    margin = float(max(2.0 * sigma / np.sqrt(len(data.points)), 0.1 * e1))
    return Recognition(best, ranking, geom, time.perf_counter() - start, method, margin)
