"""tactrec: which object is touched, and where, from minimal tactile data.

A faithful implementation of Ibrayev & Jia, "Recognition of Closed-Form and
Free-Form Surfaces from Minimal Tactile Data": three (or more) planar curves
meeting at a point give the normal and principal curvatures there
(:mod:`tactrec.estimation`); per-model curvature tables give candidate
locations (:mod:`tactrec.tables`); registration of the curves onto each model
(:mod:`tactrec.registration`) ranks the models (:mod:`tactrec.recognition`).

Quick start::

    import tactrec
    db = tactrec.build_entries(["paper-table1"])
    touch = tactrec.simulate_random_touch(db.get("ellipsoid").model, spacing=0.02, noise=0.001, rng=0)
    result = tactrec.recognize(touch, db)
    result.best, result.ranking[0].location
"""

__version__ = "0.1.0"

from .database import Database, build_database, build_entries, load_database
from .errors import InputError
from .estimation import LocalGeometry, estimate
from .io.touch import TactileData, load_touch, save_touch
from .recognition import Recognition, Recognizer, recognize
from .registration import Registration
from .simulation import simulate_random_touch, simulate_touch
from .surfaces import ClosedFormSurface, load_model

__all__ = [
    "__version__", "InputError", "TactileData", "load_touch", "save_touch", "LocalGeometry", "estimate",
    "ClosedFormSurface", "load_model", "Database", "build_database", "build_entries", "load_database",
    "Recognition", "Recognizer", "recognize", "Registration", "simulate_touch", "simulate_random_touch",
]
