"""The catalogue's index of places: every mesh's places with the rings of the surface around them
(:mod:`tactrec.surfaces.mesh_rings`, read on plane sections walked across the mesh:
:mod:`tactrec.surfaces.section_walk`), in one table that
ranks the places of every model for a touch (:mod:`.places`).  Method ``fast``'s first tier screens
the catalogue's best places in this order (:mod:`tactrec.methods.fast_index`)."""

from .places import PlaceIndex, Ranked
from ..surfaces.mesh_rings import ARCS_MM, CELL_MM, PlaceRings, model_rings, touch_rings

__all__ = ["PlaceIndex", "Ranked", "PlaceRings", "model_rings", "touch_rings", "ARCS_MM", "CELL_MM"]
