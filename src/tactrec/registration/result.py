"""Result of registering a touch onto one model."""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

from ..linalg import dot3, norm3, transform

__all__ = ["Registration", "Outcome", "local_frame", "rotations_z", "rotations_from_vectors",
           "apply_poses"]


class Outcome(enum.Enum):
    """What a search made of one model (the ``outcome`` of its :class:`Registration`)."""

    #: registered: a pose and its error
    FITTED = "fitted"
    #: ruled out, for the reason given (no candidates, the touch is larger than the model)
    REJECTED = "rejected"
    #: left unrefined by a search that stopped before it (its cheap score far behind): not ruled out
    DEFERRED = "deferred"
    #: not among the models the search was asked to search
    NOT_SEARCHED = "not searched"


@dataclasses.dataclass(frozen=True)
class Registration:
    """Best superposition of the data curves onto one model (eq. 12).

    Attributes
    ----------
    model : str
    error : float
        Registration error ``E(M)``: mean distance of the data points to the
        model (model units), or ``inf`` if the model was rejected.
    location : (3,) float
        Where the contact point lies on the model, model frame.
    rotation : (3, 3) float
        ``data2model`` rotation: ``model = scale * rotation @ data + translation``.
    translation : (3,) float
    scale : float
        Data-to-model unit conversion (1 when both use the same units).
    candidates : int
        Table rows the search started from.
    site : (s,) float
        Model-specific location (``(u, v)`` on a closed-form surface).
    phi : float or None
        Rotation of the curves about the model normal at the location, radians
        (Section 4.2: from the site's ``d1`` to the data's ``t1``).
    normal_sign : int
        +1 if the data normal was used as estimated, -1 if reversed.
    outcome : Outcome
        What the search made of the model: fitted (a pose), rejected, deferred or not searched.
    reason : str
        Why a model was not fitted (e.g. ``"no candidates"``), as printed; empty when fitted.
    spread : float
        How well the data pin the contact: the root of the trace of its covariance under the
        fit (model units; 0 where not computed).
    cheap : float
        For a model the search pruned (its poses came nowhere near the best
        error so far on other models): the best score its cheap stage reached,
        model units; ``inf`` otherwise.
    alternatives : (k, 3, 4) float or None
        Other poses the search refined on this model (``[R | t]`` each, same convention), best
        first: where a session looks for one pose that fits several touches.
    """

    model: str
    error: float
    location: np.ndarray | None = None
    rotation: np.ndarray | None = None
    translation: np.ndarray | None = None
    scale: float = 1.0
    candidates: int = 0
    site: np.ndarray | None = None
    phi: float | None = None
    normal_sign: int = 1
    outcome: Outcome = Outcome.FITTED
    reason: str = ""
    cheap: float = float("inf")
    spread: float = 0.0
    alternatives: np.ndarray | None = None

    @classmethod
    def unfitted(cls, model: str, reason: str, outcome: Outcome = Outcome.REJECTED, *, scale: float = 1.0,
                 cheap: float = float("inf")) -> "Registration":
        """A model the search did not fit (``outcome``: rejected, deferred or not searched), and why."""
        if outcome is Outcome.FITTED:
            raise ValueError("a fitted registration has a pose")
        return cls(model=model, error=float("inf"), scale=scale, outcome=outcome, reason=reason, cheap=float(cheap))

    @property
    def ok(self) -> bool:
        """Whether the model was fitted (it has a pose and an error)."""
        return self.outcome is Outcome.FITTED

    @property
    def rejected(self) -> str | None:
        """Why the model was not fitted, as printed (None when it was)."""
        return None if self.ok else self.reason

    def to_json(self) -> dict:
        if not self.ok:
            return {"model": self.model, "error": None, "rejected": self.rejected}
        out = {
            "model": self.model,
            "error": float(self.error),
            "location": np.asarray(self.location).tolist(),
            "rotation": np.asarray(self.rotation).tolist(),
            "translation": np.asarray(self.translation).tolist(),
            "candidates": int(self.candidates),
        }
        if self.scale != 1.0:
            out["scale"] = float(self.scale)
        if self.site is not None:
            out["site"] = np.asarray(self.site).tolist()
        if self.phi is not None:
            out["phi"] = float(self.phi)
        if self.spread > 0:
            out["contact_sd"] = float(self.spread)
        return out


def local_frame(normal: np.ndarray, first: np.ndarray | None = None) -> np.ndarray:
    """Rows ``t1, t2, N``: a right-handed frame with ``N`` last (Section 4.2).

    ``t1`` is ``first`` projected on the tangent plane, or any tangent.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / norm3(n)
    if first is None:
        first = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = first - dot3(first, n) * n
    t1 /= norm3(t1)
    return np.stack([t1, np.cross(n, t1), n])


def rotations_z(phis: np.ndarray) -> np.ndarray:
    """``(n, 3, 3)`` rotations by ``phis (n,)`` radians about the local normal (the frame's z)."""
    phis = np.asarray(phis, dtype=np.float64)
    c, s = np.cos(phis), np.sin(phis)
    R = np.zeros((len(phis), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return R


def rotations_from_vectors(axis_angle: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(n, 3, 3)`` from rotation vectors ``(n, 3)`` (Rodrigues)."""
    theta = np.linalg.norm(axis_angle, axis=1)
    k = axis_angle / np.where(theta > 0, theta, 1.0)[:, None]
    K = np.zeros((len(k), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (k[:, :, None] * k[:, None, :] - np.eye(3))      # K K = k k^T - I


def apply_poses(R: np.ndarray, t: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Points ``x (m, 3)`` under each pose ``R (h, 3, 3), t (h, 3)``: ``(h, m, 3)``."""
    return transform(R, t, np.asarray(x, dtype=np.float64))
