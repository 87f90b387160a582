"""Sessions: several touches of one still object, recognised together.

* :mod:`.core` -- :class:`Session`, the steps of an add (the module text there);
* :mod:`.add` -- one add's work, step 5's searches among it (:class:`~.add.Add`);
* :mod:`.joint` -- steps 2-4 and 6, the joint fit, a collaborator of the add;
* :mod:`.touches` -- the touches, and what the fit test measures on them;
* :mod:`.record` -- one :class:`TouchRecord` per touch, and the one fit test (:func:`fits`);
* :mod:`.fit` -- a model's candidate poses scored on every touch and refined jointly;
* :mod:`.family` -- the poses along the motions the touches leave free;
* :mod:`.result` -- :class:`Hypothesis` and :class:`SessionResult`.
"""

from .core import FLOOR, STAGES, STARTS, Session
from .record import CONSISTENT_SE, TouchRecord, allowed_fit, fits
from .result import Hypothesis, SessionResult

__all__ = ["Session", "SessionResult", "Hypothesis", "TouchRecord", "CONSISTENT_SE", "STAGES", "STARTS", "FLOOR",
           "allowed_fit", "fits"]
