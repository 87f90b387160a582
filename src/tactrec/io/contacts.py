"""Single contacts: isolated points a probe or a force/torque sensor records, each with an optional
outward normal, its uncertainty, and the point's own.

The format (docs/formats.md, "Single contacts")::

    {"units": "mm", "contacts": [{"point": [x, y, z], "normal": [x, y, z], "normal_sd_deg": 5,
                                  "point_sd": 0.1}, ...]}

``normal`` points out of the object; ``normal_sd_deg`` is its standard deviation in degrees;
``point_sd`` the point's per coordinate, data units.  A contact without a normal is scored but
poses nothing (:mod:`tactrec.engine.contacts`); a normal without its uncertainty poses hypotheses
but rules none out; a touch without any ``point_sd`` is read as exact, as noise-free curves are
(its fit limit is the method's floor x its reach).  Everything is checked here, at the boundary.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InputError
from ..linalg import eigvalsh, gram, norm3, times
from .values import _check_reach, _vector, number

__all__ = ["Contacts", "parse_contacts", "MIN_CONTACTS", "FIELDS", "spread_problem"]

#: a touch of contacts is posed from this many (recognised alone, or a session's pooled): fewer leave
#: the rotation about the normals free
MIN_CONTACTS = 3
#: what a contact may carry
FIELDS = ("point", "normal", "normal_sd_deg", "point_sd")
#: the largest normal uncertainty a contact may state, degrees: beyond it a normal says nothing
MAX_NORMAL_SD = 90.0


@dataclasses.dataclass(frozen=True)
class Contacts:
    """Isolated contacts, data frame.

    Attributes
    ----------
    points : (n, 3) float
    normals : (n, 3) float
        Unit outward normals; NaN rows where a contact gives none.
    normal_sd : (n,) float
        Each normal's standard deviation, degrees; NaN where not given.
    point_sd : (n,) float
        Each point's standard deviation per coordinate, data units; NaN where not given.
    """

    points: np.ndarray
    normals: np.ndarray
    normal_sd: np.ndarray
    point_sd: np.ndarray

    def __len__(self) -> int:
        return len(self.points)

    @property
    def has_normal(self) -> np.ndarray:
        """Which contacts give a normal ``(n,)``."""
        return np.isfinite(self.normals[:, 0])

    @property
    def noise(self) -> float:
        """The points' noise sigma per coordinate (data units): the median of those given, 0 where none is."""
        given = self.point_sd[np.isfinite(self.point_sd)]
        return float(np.median(given)) if len(given) else 0.0

    def rows(self, index) -> "Contacts":
        """The contacts ``index`` selects (a slice, or indices), in that order."""
        return Contacts(self.points[index], self.normals[index], self.normal_sd[index], self.point_sd[index])

    def joined(self, other: "Contacts") -> "Contacts":
        """These contacts and then ``other``'s (same frame)."""
        return Contacts(*(np.concatenate([a, b]) for a, b in zip(dataclasses.astuple(self), dataclasses.astuple(other))))

    def transformed(self, R: np.ndarray, t: np.ndarray, scale: float) -> "Contacts":
        """The contacts in another frame: ``x -> scale * (R x + t)``."""
        return dataclasses.replace(self, points=scale * (times(self.points, R.T) + t),
                                   normals=times(self.normals, R.T), point_sd=scale * self.point_sd)

    def to_json(self) -> list:
        out = []
        for p, n, a, s in zip(self.points, self.normals, self.normal_sd, self.point_sd):
            item = {"point": p.tolist()}
            if np.isfinite(n[0]):
                item["normal"] = n.tolist()
            if np.isfinite(a):
                item["normal_sd_deg"] = float(a)
            if np.isfinite(s):
                item["point_sd"] = float(s)
            out.append(item)
        return out


def parse_contacts(obj, source: str) -> Contacts:
    """The ``contacts`` list of a touch file, checked: at least one contact, each a ``point`` with an
    optional non-zero ``normal``, ``normal_sd_deg`` in (0, 90] beside a normal, ``point_sd`` >= 0."""
    if not isinstance(obj, list) or not obj:
        raise InputError("'contacts' must be a non-empty list of {\"point\": [x, y, z], ...}", source)
    points, normals, sds, psds = [], [], [], []
    for i, c in enumerate(obj, start=1):
        if not isinstance(c, dict) or "point" not in c:
            raise InputError(f"contact {i} must be an object with a 'point'", source)
        unknown = sorted(set(c) - set(FIELDS))
        if unknown:
            raise InputError(f"contact {i}: unknown field {unknown[0]!r} (a contact has {', '.join(FIELDS)})", source)
        points.append(_vector(c["point"], f"contact {i} point", source))
        n = np.full(3, np.nan)
        if "normal" in c:
            n = _vector(c["normal"], f"contact {i} normal", source)
            length = norm3(n)
            if not length > 0:
                raise InputError(f"contact {i}: 'normal' must be a non-zero direction", source)
            n = n / length
        normals.append(n)
        sd = np.nan
        if "normal_sd_deg" in c:
            if "normal" not in c:
                raise InputError(f"contact {i}: 'normal_sd_deg' without a 'normal'", source)
            sd = number(c["normal_sd_deg"], f"contact {i} normal_sd_deg", source)
            if not 0.0 < sd <= MAX_NORMAL_SD:
                raise InputError(f"contact {i}: 'normal_sd_deg' must lie in (0, {MAX_NORMAL_SD:g}] (got {sd:g})",
                                 source)
        sds.append(sd)
        psd = np.nan
        if "point_sd" in c:
            psd = number(c["point_sd"], f"contact {i} point_sd", source)
            if psd < 0:
                raise InputError(f"contact {i}: 'point_sd' must be >= 0 (got {psd:g})", source)
        psds.append(psd)
    arr = np.array(points)
    _check_reach([arr], source)
    return Contacts(arr, np.array(normals), np.array(sds), np.array(psds))


def spread_problem(contacts: Contacts) -> str | None:
    """Why ``contacts`` cannot be posed (None where they can): fewer than :data:`MIN_CONTACTS`, none
    with a normal (a normal anchors every hypothesis), or all on one line (the turn about it free;
    with the line's length as scale, a second axis shorter than a millionth of it)."""
    n = len(contacts)
    if n < MIN_CONTACTS:
        return f"{n} contact{'s' if n != 1 else ''}; at least {MIN_CONTACTS} are needed to pose an object"
    if not contacts.has_normal.any():
        return "no contact gives a normal; at least one is needed to pose an object"
    x = contacts.points - contacts.points.mean(axis=0)
    sv = np.sqrt(np.maximum(eigvalsh(gram(x)), 0.0))[::-1]
    if not sv[0] > 0 or sv[1] <= 1e-6 * sv[0]:
        return "contacts without enough spread: they lie on one line (or at one place)"
    return None
