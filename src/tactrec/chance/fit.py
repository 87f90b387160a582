"""Fitting the null model of chance fits on a database's own models (``tactrec calibrate``).

Each model is touched ``touches`` times at seeded random places, alternately

* *small and noisy*: curves of a length drawn log-uniformly over the lower half of ``lengths``
  (in ``log``), noise drawn log-uniformly over ``noise``, sampling planes 20-45 degrees apart;
* *larger and clean*: a length over the upper half, no noise, planes 45-75 degrees apart, every
  other one at a random vertex of a mesh (where a machined part's edges and corners are: the
  places its touches tell least well from another part's);

61 points a curve.  With ``kinds`` beyond curves, as many touches a model of each other kind
(:data:`~tactrec.chance.KINDS`), half at random places and half at random vertices of a mesh:

* *patches*: height maps of :data:`~tactrec.simulation.PATCH_POINTS` pixels over a disc of a radius
  drawn log-uniformly over ``PATCH_RADII``, depth noise log-uniformly over ``PATCH_NOISE``, every
  other one blurred by a gel of sigma drawn uniformly over ``PATCH_BLUR``;
* *contacts*: a count drawn uniformly over ``CONTACTS`` of single contacts spread over the model,
  position noise log-uniformly over ``CONTACT_NOISE``, each normal tilted by a sigma drawn uniformly
  over ``NORMAL_SD`` degrees and stated.

Each touch is recognised with every model, and again among the others only
(the touched model left out); the two recognitions' best fits give the calibration's statistics
(:mod:`tactrec.chance`).  The touches are of the catalogue's own surfaces, so the null model
learns how alike they are; their kinds span the touches a probe or a fingertip makes, so the
resolving power of a new touch falls among them.  Everything is drawn from ``seed``.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..probability import fit_limit
from ..simulation import simulate_random_touch
from . import SPAN, NullModel, catalogue_key, statistics

__all__ = ["calibrate", "fits", "LENGTHS", "NOISE", "TOUCHES", "POINTS", "PATCH_RADII", "PATCH_NOISE", "PATCH_BLUR",
           "CONTACTS", "CONTACT_NOISE", "NORMAL_SD"]

#: the range of the calibration touches' curve lengths, data units (the models' usual millimetres)
LENGTHS = (8.0, 32.0)
#: the range of the noisy touches' noise sigma, data units
NOISE = (0.01, 0.08)
#: touches per model
TOUCHES = 16
#: points per calibration curve
POINTS = 61
#: the calibration patches' radii, depth noise sigmas and gel blur sigmas, data units
PATCH_RADII, PATCH_NOISE, PATCH_BLUR = (2.0, 10.0), (0.005, 0.05), (0.05, 0.3)
#: the calibration contacts' counts, position noise sigmas (data units) and normals' sigmas (degrees)
CONTACTS, CONTACT_NOISE, NORMAL_SD = (3, 12), (0.02, 0.2), (2.0, 10.0)


def fits(recognition, floor: float) -> tuple[float, float, float]:
    """A recognition's ``(x1, x2, r)`` as :func:`~tactrec.chance.statistics` reads
    them (``SPAN`` for a fit it has not), the one path calibration and recognition share."""
    touch = recognition.touch
    limit = max(fit_limit(touch, floor), touch.fit)
    if recognition.evidence is not None and len(recognition.evidence.models):
        return statistics(recognition.evidence)
    return SPAN, SPAN, float(np.log10(touch.radius / limit))


def _touch(model, rng, kind: int, lengths, noise):
    """Calibration touch of ``kind`` (0: small and noisy; 1: clean at a random place; 2: clean at a
    random vertex of a mesh, where a machined part's edges and corners are)."""
    small = kind == 0
    lo, hi = np.log(lengths[0]), np.log(lengths[1])
    mid = 0.5 * (lo + hi)
    length = float(np.exp(rng.uniform(lo, mid) if small else rng.uniform(mid, hi)))
    sigma = float(np.exp(rng.uniform(np.log(noise[0]), np.log(noise[1])))) if small else 0.0
    angle = float(rng.uniform(20.0, 45.0) if small else rng.uniform(45.0, 75.0))
    options = dict(points=POINTS, spacing=length / (POINTS - 1), angle=angle, noise=sigma, noise_kind="gaussian",
                   outward=not small)
    if kind == 2 and hasattr(model, "vertices"):
        try:
            return simulate_random_touch(model, rng=rng, attempts=50, vertices=True, **options)
        except InputError:
            raise
        except ValueError:
            pass                               # no vertex takes it: a random place does
    return simulate_random_touch(model, rng=rng, **options)


def _log_uniform(rng, bounds) -> float:
    return float(np.exp(rng.uniform(np.log(bounds[0]), np.log(bounds[1]))))


def _other(model, rng, kind: str, i: int):
    """Calibration touch ``i`` of ``kind`` (``patch`` or ``contacts``) of ``model`` (module text)."""
    from ..simulation import simulate_contacts, simulate_patch

    if kind == "contacts":
        count = int(rng.integers(CONTACTS[0], CONTACTS[1] + 1))
        return simulate_contacts(model, count, noise=_log_uniform(rng, CONTACT_NOISE),
                                 normal_sd=float(rng.uniform(*NORMAL_SD)), rng=rng)
    options = dict(radius=_log_uniform(rng, PATCH_RADII), noise=_log_uniform(rng, PATCH_NOISE),
                   blur=float(rng.uniform(*PATCH_BLUR)) if i % 2 else 0.0)
    return simulate_random_touch(model, rng=rng, attempts=50, vertices=bool(i % 2), maker=simulate_patch, **options)


def calibrate(recognizer, *, touches: int = TOUCHES, seed: int = 0, lengths=LENGTHS, noise=NOISE,
              kinds=("curves",), progress=None) -> NullModel:
    """The null model of ``recognizer``'s models (a :class:`~tactrec.recognition.Recognizer` of at
    least two), from ``touches`` seeded touches of each model and each of ``kinds`` (module text).
    ``progress``: called with each touch's model name as it is done."""
    from . import KINDS

    entries = list(recognizer.models)
    if len(entries) < 2:
        raise InputError("a null model needs at least two models: one is left out of each touch", "calibrate")
    if touches < 2:
        raise InputError(f"calibrate with at least two touches per model, not {touches}", "calibrate")
    if not (0 < lengths[0] <= lengths[1] and 0 < noise[0] <= noise[1]):
        raise InputError(f"calibration lengths {lengths} and noise {noise} are not increasing ranges", "calibrate")
    if not kinds or not set(kinds) <= set(KINDS):
        raise InputError(f"calibrate touches of kinds among {', '.join(KINDS)}, not {kinds!r}", "calibrate")
    names = [e.name for e in entries]
    floor = recognizer.floor
    r, known, unknown, touched, made = [], [], [], [], []
    order = ((k, m, i) for k in KINDS if k in kinds for m in range(len(entries)) for i in range(int(touches)))
    for kind, m, i in order:
        entry, others = entries[m], names[:m] + names[m + 1:]
        # a curve's seed as before kinds were calibrated: the curves' statistics do not move
        extra = [] if kind == "curves" else [KINDS.index(kind)]
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), m, i] + extra))
        try:
            if kind == "curves":
                data = _touch(entry.model, rng, 0 if i % 2 == 0 else 1 + (i // 2) % 2, lengths, noise)
            else:
                data = _other(entry.model, rng, kind, i)
        except ValueError:
            continue                           # no place of this model takes such a touch
        whole = fits(recognizer.recognize(data), floor)
        left = fits(recognizer.recognize(data, among=others), floor)
        r.append(whole[2])
        touched.append(entry.name)
        made.append(kind)
        known.append(whole[:2])
        unknown.append(left[:2])
        if progress is not None:
            progress(entry.name)
    if not r:
        raise InputError("no model took a calibration touch (are the lengths in the models' units?)", "calibrate")
    return NullModel(catalogue_key(entries), np.array(r), np.array(known).reshape(-1, 2),
                     np.array(unknown).reshape(-1, 2), tuple(touched), recognizer.method.name, int(seed), int(touches),
                     kinds=tuple(made))
