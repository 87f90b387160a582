"""The offline viewer (``tactrec show``): a recognition drawn in 3-D in one HTML file.

:func:`~tactrec.viewer.scene.touch_scene` turns a result into plain arrays (a
*scene*); :func:`~tactrec.viewer.page.page` turns a scene into a self-contained
page; :func:`write_view` writes it atomically.
"""

from __future__ import annotations

from ..io.atomic import write_text_atomic
from .page import page
from .scene import touch_scene

__all__ = ["touch_scene", "page", "write_view"]


def write_view(path, scene: dict) -> None:
    """Write ``scene``'s page to ``path`` (atomically: a reader never sees half a file)."""
    write_text_atomic(path, page(scene))
