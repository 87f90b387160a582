"""``tactrec serve``: the database loaded once, one JSON request per line in, one JSON answer per line out.

A robot's stack (a ROS node, a script in any language) keeps one process and pays no start-up per
touch (docs/formats.md, The service).  Each request is a JSON object with an optional ``id``
(echoed in the answer) and exactly one of:

* ``"recognize": TOUCH`` -- one touch (the fields of a tactile data file); the answer has the
  fields of ``tactrec recognize --json``;
* ``"session": NAME, "add": TOUCH`` -- a touch of that session (the fields of a session file's
  touch: ``sensor2world``, or ``missed`` for an approach line that met nothing); the session is
  opened by its first add; the answer has the fields of ``tactrec recognize SESSION --json``;
* ``"session": NAME, "next": {"radius": R, "angle": A, "seed": S}`` (each optional) -- the
  answer has the fields of ``tactrec next --json``;
* ``"session": NAME, "close": true`` -- the session is forgotten.

Everything a request does is one call of the Python API: :meth:`Recognizer.recognize
<tactrec.recognition.Recognizer.recognize>`, :meth:`Recognizer.session
<tactrec.recognition.Recognizer.session>`, :meth:`Session.add <tactrec.session.Session.add>` (or
:meth:`~tactrec.session.Session.add_miss`) and :meth:`Session.next <tactrec.session.Session.next>`;
the request's JSON is read by :func:`tactrec.io.touch.parse_touch` and
:func:`tactrec.io.session.parse_session_touch`.

On a cluster (``--cluster``), a request some of whose models could not be searched (their workers
lost, none left to load them) gets ``{"id": ..., "error": "...", "unavailable": [models]}`` and
the service ends (:class:`~tactrec.errors.ShardsUnavailable`; the command exits 3).

A bad request gets ``{"id": ..., "error": "..."}`` and the service goes on: a request is checked
before it changes anything, and a session's add that fails leaves the session as it was, so no
request reaches another session.  A line longer than :data:`MAX_LINE` bytes is refused unread.
"""

from __future__ import annotations

import json

import numpy as np

from .errors import InputError, ShardsUnavailable
from .io.meeting import check_meeting
from .io.session import SessionMiss, parse_session_touch
from .io.touch import parse_touch, read_json
from .units import conversion

__all__ = ["Service", "serve", "default_radius", "MAX_LINE", "DEFAULT_RADIUS_MM"]

#: the longest request line read, bytes (a touch of a few thousand points is a few hundred kilobytes)
MAX_LINE = 16 * 2 ** 20
#: how far from an earlier contact ``next`` may propose a touch, millimetres (in the session's units)
DEFAULT_RADIUS_MM = 40.0
def default_radius(units: str | None) -> float:
    """``next``'s default reach, :data:`DEFAULT_RADIUS_MM` in ``units`` (None: the models' own, taken as mm)."""
    return DEFAULT_RADIUS_MM * (conversion("mm", units) if units else 1.0)


#: what a request may hold beside its ``id``
_KINDS = {"recognize": set(), "add": {"session"}, "next": {"session"}, "close": {"session"}}


class Service:
    """Requests (module text) against one :class:`~tactrec.recognition.Recognizer`.

    Parameters
    ----------
    recognizer : tactrec.recognition.Recognizer
        The database and method, kept for the service's life.
    seed : int
        ``next``'s seed where a request gives none.
    """

    def __init__(self, recognizer, *, seed: int = 0):
        self.recognizer = recognizer
        self.seed = seed
        self.sessions: dict[str, object] = {}
        self.served = 0

    def answer(self, line: str | bytes) -> dict:
        """The answer to one request line: never raises for anything the line holds."""
        self.served += 1
        source = f"request {self.served}"
        ident = None
        try:
            if isinstance(line, bytes):
                line = line.decode("utf-8")
            obj = read_json(line, source)
            if isinstance(obj, dict):
                ident = obj.get("id")
                if not (ident is None or isinstance(ident, (str, int, float, bool))):
                    ident = None
                    raise InputError("'id' must be a string or a number", source)
            out = self.request(obj, source=source)
        except InputError as exc:
            return {"id": ident, "error": str(exc)}
        except ShardsUnavailable as exc:          # a cluster's models that could not answer: the service ends
            exc.answer = {"id": ident, "error": f"{source}: {exc}", "unavailable": exc.models}
            raise
        except UnicodeDecodeError:
            return {"id": ident, "error": f"{source}: not UTF-8 text"}
        except (ValueError, TypeError, OverflowError, ArithmeticError) as exc:
            return {"id": ident, "error": f"{source}: {exc}"}
        except Exception as exc:  # noqa: BLE001 -- a request never ends the service
            return {"id": ident, "error": f"{source}: internal error ({type(exc).__name__}: {exc})"}
        return dict({"id": ident}, **out)

    def request(self, obj, *, source: str = "request") -> dict:
        """The answer's fields for the request ``obj`` (a parsed JSON object, module text); raises
        :class:`~tactrec.errors.InputError` for a bad one, having changed nothing."""
        if not isinstance(obj, dict):
            raise InputError("a request is a JSON object", source)
        kinds = [k for k in _KINDS if k in obj]
        if len(kinds) != 1:
            raise InputError("a request has exactly one of 'recognize', 'add', 'next' and 'close'", source)
        kind = kinds[0]
        extra = set(obj) - {"id", kind} - _KINDS[kind]
        if extra:
            raise InputError(f"the {kind!r} request has no {sorted(extra)[0]!r}", source)
        if kind == "recognize":
            data = parse_touch(obj["recognize"], source)
            check_meeting(data)
            return self.recognizer.recognize(data).to_json()
        name = obj.get("session")
        if not isinstance(name, str) or not name:
            raise InputError(f"the {kind!r} request names its 'session' (a non-empty string)", source)
        if kind == "add":
            return self._add(name, obj["add"], source)
        session = self.sessions.get(name)
        if session is None:
            raise InputError(f"no session {name!r} is open (a session opens with its first 'add')", source)
        if kind == "close":
            if obj["close"] is not True:
                raise InputError("'close' must be true", source)
            del self.sessions[name]
            return {"session": name, "closed": True, "touches": len(session.records)}
        return self._next(session, obj["next"], source)

    def _add(self, name: str, item, source: str) -> dict:
        session = self.sessions.get(name)
        units = session.records[0].given.data.units if session is not None and session.records else None
        touch = parse_session_touch(item, source, units)
        if isinstance(touch, SessionMiss) and units is not None and touch.units not in (None, units):
            raise InputError(f"this missed line is in {touch.units!r}, the session in {units!r}", source)
        if session is None:
            if isinstance(touch, SessionMiss):
                raise InputError("a session opens with a touch that met the object, not a missed line", source)
            session = self.recognizer.session()
        if isinstance(touch, SessionMiss):
            result = session.add_miss(touch.line, (touch.rotation, touch.translation))
        else:
            result = session.add(touch.data, (touch.rotation, touch.translation))
        self.sessions[name] = session
        return dict({"session": name}, **result.to_json())

    def _next(self, session, options, source: str) -> dict:
        if not isinstance(options, dict) or set(options) - {"radius", "angle", "seed"}:
            raise InputError("'next' is an object with at most 'radius', 'angle' and 'seed'", source)
        units = session.records[0].given.data.units
        radius = _positive(options.get("radius", default_radius(units)), "radius", source)
        angle = _positive(options.get("angle", 60.0), "angle", source)
        seed = options.get("seed", self.seed)
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise InputError("'seed' must be a non-negative whole number", source)
        if not session.result.ranking:
            raise InputError("no model fits any touch of the session: nothing to propose", source)
        return session.next(radius=radius, angle=angle, rng=seed).to_json()


def _positive(value, what: str, source: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise InputError(f"{what!r} must be a positive number (got {value!r})", source)
    return float(value)


def serve(recognizer, stdin, stdout, *, seed: int = 0) -> int:
    """Answer each line of the binary stream ``stdin`` on the text stream ``stdout`` until the end of
    the input: the number of requests answered."""
    service = Service(recognizer, seed=seed)
    while True:
        line = stdin.readline(MAX_LINE + 1)
        if not line:
            return service.served
        if len(line) > MAX_LINE:
            while line and not line.endswith(b"\n"):             # the rest of an overlong line, unread
                line = stdin.readline(MAX_LINE)
            service.served += 1
            out = {"id": None, "error": f"request {service.served}: a request line is at most {MAX_LINE} bytes"}
        elif not line.strip():
            continue
        else:
            try:
                out = service.answer(line)
            except ShardsUnavailable as exc:          # answered, naming the models; then the service ends
                stdout.write(json.dumps(exc.answer) + "\n")
                stdout.flush()
                raise
        try:
            text = json.dumps(out, allow_nan=False)
        except ValueError:                            # a number JSON cannot carry: never a line a client cannot read
            text = json.dumps({"id": out.get("id"), "error": f"request {service.served}: the answer holds a "
                               "number JSON cannot carry"})
        stdout.write(text + "\n")
        stdout.flush()
