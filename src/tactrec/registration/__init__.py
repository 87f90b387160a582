"""Registration of data curves onto one model (paper Sections 3.2.2, 4.2, 5.3).

* :mod:`.closedform_paper` -- the paper's steepest descent on ``E(u, v, phi)`` (eq. 11);
* :mod:`.mesh_paper` -- the paper's plane sections (eq. 15) and greedy walk;
* :mod:`.closedform_fast`, :mod:`.mesh_fast` -- the steps of method ``fast``
  (six-DoF Gauss-Newton), scheduled by :mod:`tactrec.methods.fast`;
* :mod:`.result` -- the :class:`Registration` result and pose arithmetic.

Which of them a recognition uses is the method's choice (:mod:`tactrec.methods`).
"""

from __future__ import annotations

from .result import Outcome, Registration, local_frame

__all__ = ["Registration", "Outcome", "local_frame"]
