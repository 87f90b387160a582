"""The offline viewer (``tactrec show``): a recognition drawn in 3-D in one HTML file.

:func:`~tactrec.viewer.scene.touch_scene` turns a result into plain arrays (a
*scene*); :func:`~tactrec.viewer.page.page` turns a scene into a self-contained
page; :func:`write_view` writes it atomically.  :func:`~tactrec.viewer.session.session_scene`
is a session's scene (every touch, the proposed next one);
:func:`~tactrec.viewer.still.render_still` renders a page's still in a headless browser.
"""

from __future__ import annotations

from ..io.atomic import write_text_atomic
from .page import page
from .scene import touch_scene
from .session import session_scene
from .still import render_still

__all__ = ["touch_scene", "session_scene", "page", "write_view", "render_still"]


def write_view(path, scene: dict) -> None:
    """Write ``scene``'s page to ``path`` (atomically: a reader never sees half a file)."""
    write_text_atomic(path, page(scene))
