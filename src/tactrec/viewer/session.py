"""A session's scene: every touch in its own colour on each hypothesis, and the proposed next touch.

A session's result (:meth:`tactrec.session.result.SessionResult.to_json`) gives each model one
pose of the *world* (``model = scale R world + t``); each view draws every touch's curves (mapped
from its sensor into the world by its ``sensor2world``, then onto the model) in the touch's
colour, the touches the session calls *slipped* faded and their meeting point crossed, the lines
that met nothing grey, and the proposed next touch (:meth:`tactrec.proposal.Proposal.to_json`,
world frame) in magenta: its approach line, its contact, and its curves as that view's
hypothesis predicts them (:func:`tactrec.proposal.predict.predicted`; straight chords where that
surface will not take them).
"""

from __future__ import annotations

import types

import numpy as np

from .scene import COLOURS, others, placed, pose_of, view

__all__ = ["session_scene", "NEXT_COLOUR", "MISSED_COLOUR"]

NEXT_COLOUR, MISSED_COLOUR = "#e000e0", "#888888"
PREDICTED_POINTS = 21          # points on each drawn proposed curve


def _meeting(curves: list) -> np.ndarray:
    from ..io.meeting import find_contact

    return find_contact([np.asarray(c, float) for c in curves])


def _proposed_curves(model, entry: dict, proposal: dict, length: float) -> list[np.ndarray]:
    """The proposal's curves on ``model`` under ``entry``'s pose, model frame, each ``length`` long (none
    for a proposed single contact)."""
    from ..proposal.predict import predicted

    if proposal.get("directions") is None:
        return []
    R, t, scale = pose_of(entry)
    contact = np.asarray(proposal["contact"], float)
    directions = np.asarray(proposal["directions"], float)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hypothesis = types.SimpleNamespace(rotation=R, translation=t, scale=scale)
    spacing = length / (PREDICTED_POINTS - 1)
    found = predicted(model, hypothesis, contact, directions, points=PREDICTED_POINTS, spacing=spacing)
    if found is not None:
        x, kept = found
        x, kept = x.reshape(len(directions), PREDICTED_POINTS, 3), kept.reshape(len(directions), PREDICTED_POINTS)
        return [placed(entry, x[i][kept[i]]) for i in range(len(directions))]
    offsets = (np.arange(PREDICTED_POINTS) - (PREDICTED_POINTS - 1) / 2.0) * spacing
    return [placed(entry, contact + offsets[:, None] * d) for d in directions]


def _centre(model) -> np.ndarray:
    """The middle of ``model``'s bounding box (a closed-form surface's sampled grid)."""
    from .scene import surface_mesh

    vertices = np.asarray(model.vertices, float) if getattr(model, "kind", None) == "mesh" else \
        surface_mesh(model, faces=200)[0]
    return 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))


def session_scene(result: dict, touches: list, models: dict, *, proposal: dict | None = None, shown: int = 5,
                  faces: int = 10000, runner_faces: int = 4000, title: str = "") -> dict:
    """The scene of a session's recognition.

    Parameters
    ----------
    result : dict
        The session's JSON result (``ranking`` with each model's world pose, ``slipped``, ``normal``).
    touches : list
        The session's items in order (:class:`~tactrec.io.session.SessionTouch`, or
        :class:`~tactrec.io.session.SessionMiss` for a line that met nothing).
    models : dict
        Name to model, for at least the models shown.
    proposal : dict, optional
        ``tactrec next``'s proposal (world frame); drawn when it proposes a contact.
    shown, faces, runner_faces : int
        As :func:`tactrec.viewer.scene.touch_scene`.
    """
    registered = [r for r in result.get("ranking", []) if r.get("error") is not None][:shown]
    slipped = set(result.get("slipped", []))
    worlds = [t.in_world().curves for t in touches if hasattr(t, "data")]
    misses = [t.line.transformed(t.rotation, t.translation) for t in touches if not hasattr(t, "data")]
    meetings = [_meeting(c) for c in worlds]
    lengths = [float(np.sum(np.linalg.norm(np.diff(np.asarray(c, float), axis=0), axis=1)))
               for curves in worlds for c in curves]
    proposed = proposal if proposal is not None and proposal.get("contact") is not None else None
    legend = [{"name": f"touch {k + 1}" + (" (slipped)" if k in slipped else ""),
               "colour": COLOURS[k % len(COLOURS)], "faded": k in slipped} for k in range(len(worlds))]
    legend += [{"name": f"line {k + 1}: met nothing", "colour": MISSED_COLOUR, "faded": False}
               for k in range(len(misses))]
    if proposed is not None:
        legend.append({"name": f"next touch (expected gain {float(proposed.get('gain', 0.0)):.2f} bits)",
                       "colour": NEXT_COLOUR, "faded": False})
    views = []
    for r in registered:
        model = models[r["model"]]
        curves, marks, lines = [], [], []
        for k, touch in enumerate(worlds):
            colour, faded = COLOURS[k % len(COLOURS)], k in slipped
            name = legend[k]["name"]
            curves += [{"points": placed(r, c), "colour": colour, "name": name, "opacity": 0.35 if faded else 1.0}
                       for c in touch]
            marks.append({"point": placed(r, meetings[k]), "name": name, "colour": colour,
                          "symbol": "x" if faded else "circle"})
        for k, line in enumerate(misses):
            ends = np.stack([line.start, line.start + line.length * line.direction])
            lines.append({"points": placed(r, ends), "name": f"line {k + 1}: met nothing", "colour": MISSED_COLOUR})
        if proposed is not None:
            a = proposed.get("approach")
            if a is not None:
                start, direction = np.asarray(a["start"], float), np.asarray(a["direction"], float)
                ends = np.stack([start, start + float(a["length"]) * direction])
                lines.append({"points": placed(r, ends), "name": "next: approach", "colour": NEXT_COLOUR})
            length = float(np.median(lengths)) if lengths else 1.0
            curves += [{"points": c, "name": f"next: curve {i + 1}", "colour": NEXT_COLOUR}
                       for i, c in enumerate(_proposed_curves(model, r, proposed, length))]
            marks.append({"point": placed(r, np.asarray(proposed["contact"], float)), "name": "next: contact",
                          "colour": NEXT_COLOUR, "symbol": "diamond"})
        # the contact drawn and looked at: the latest touch that fits (its meeting point, on the surface)
        last = max((k for k in range(len(worlds)) if k not in slipped), default=len(worlds) - 1)
        anchor = placed(r, meetings[last]) if worlds else np.asarray(r["location"], float)
        outward = anchor - _centre(model)
        normal = pose_of(r)[0] @ np.asarray(result.get("normal", [0.0, 0.0, 1.0]), float)
        if last != len(worlds) - 1:
            normal = outward                       # the estimate's normal is the latest touch's, which slipped
        elif normal @ outward < 0:
            normal = -normal                       # a session's normal has no side: drawn away from the centre
        views.append(view(r, model, faces=faces if not views else runner_faces, curves=curves, normal=normal,
                          marks=marks, lines=lines, towards=anchor, contact=anchor))
    return {"kind": "session", "title": title, "best": result.get("best"), "confidence": result.get("confidence"),
            "unknown": result.get("unknown"), "views": views, "others": others(result, views), "legend": legend}
