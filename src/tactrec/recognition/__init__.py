"""Recognition: which model the touch came from, and where (paper Section 3.3).

The touch's features are computed once (:class:`tactrec.features.Touch`);
the method (:mod:`tactrec.methods`) registers the data on the models, which are
ranked by their registration error ``E(M)`` (eq. 9); the most probable is recognised,
the least error of equals (:func:`tactrec.probability.most_probable`, the rule a
session follows too).

* :mod:`.recognizer` -- :class:`Recognizer`, the one path from a touch to a result, and
  :func:`recognize`, the one-off call;
* :mod:`.again` -- the searches made again within it (a slipping sensor's curve ends, curves that
  meet at more than one point);
* :mod:`.result` -- the :class:`Recognition` it returns.
"""

from ..probability import FLOOR
from ..runner import default_workers
from .recognizer import OFF_SCALE, ModelEntry, Recognizer, check_scale, recognize
from .result import LOCATED, Recognition

__all__ = ["Recognition", "Recognizer", "recognize", "ModelEntry", "default_workers", "FLOOR", "LOCATED", "OFF_SCALE",
           "check_scale"]
