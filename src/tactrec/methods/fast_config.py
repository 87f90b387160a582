"""Method ``fast``'s options and its fixed schedule (see :mod:`tactrec.methods.fast`).

:class:`FastConfig` holds the few options a user may set, each with its unit and its effect.  What
the search's stages need beyond them is fixed: the tiers of the schedule (:data:`TIERS`) and the
constants of each stage, named on the config with the reason for each value.  They were measured on
the benches of ``tactrec bench`` (``fast-vs-paper``, ``fit-limit --scans other``) and are not meant
to be set per touch.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ..registration import closedform_fast
from .base import Config

__all__ = ["FastConfig", "Tier", "TIERS", "EXHAUSTIVE"]


@dataclasses.dataclass(frozen=True)
class Tier:
    """One step of the schedule: the best ``places`` places per model and normal (None: every
    vertex; with ``folded``, of the folded places alone, for a touch whose normals disagree across
    scales), posed by their principal ``"frames"`` or at ``"all"`` 30-degree rotations, with the
    normal as estimated or also ``tilt`` degrees off four ways; or every place at every rotation,
    screened on the model's distance field (``"field"``: :mod:`tactrec.engine.screen`), with the
    data's normals or, for ``tilt > 0``, with normals tilted every ``tilt_step`` degrees out to
    ``tilt`` (:func:`tactrec.engine.screen.tilted_normals`).  An ``indexed`` field tier takes the
    catalogue's best ``places`` x models places by the index of places instead, in rounds
    (:mod:`tactrec.methods.fast_index`), and each model's own best by curvature for a touch the
    index cannot read."""

    places: int | None
    rotations: str = "frames"
    tilt: float = 0.0
    folded: bool = False
    indexed: bool = False

    def __post_init__(self):
        if self.places is not None and (not isinstance(self.places, int) or self.places < 1):
            raise ValueError(f"a tier's places must be a whole number >= 1 or None, got {self.places!r}")
        if self.rotations not in ("frames", "all", "field"):
            raise ValueError(f"a tier's rotations are 'frames', 'all' or 'field', got {self.rotations!r}")
        if not 0.0 <= self.tilt < 90.0:
            raise ValueError(f"a tier's tilt is in [0, 90) degrees, got {self.tilt!r}")
        if self.folded and self.rotations != "field":
            raise ValueError("a tier of folded places is a field tier")
        if self.indexed and (self.rotations != "field" or self.folded or self.tilt > 0 or self.places is None):
            raise ValueError("an indexed tier is an untilted field tier of a number of places a model")


#: the default schedule, coarse to fine: the catalogue's best 500 places a model by the index of
#: places (each model's best 500 by curvature for a touch the index cannot read) screened on the field, the
#: best 500 folded places (for a touch whose normals disagree across scales), the 24 places whose
#: curvature matches best posed by their frames, every place on the field, every place with the
#: normal tilted out to 60 degrees
TIERS = (Tier(500, "field", indexed=True), Tier(500, "field", folded=True), Tier(24), Tier(None, "field"),
         Tier(None, "field", 60.0))
#: the exhaustive reference: every vertex, every 30 degrees
EXHAUSTIVE = (Tier(None, "all"),)


@dataclasses.dataclass(frozen=True)
class FastConfig(Config):
    """Options of the ``fast`` method (see :mod:`tactrec.methods.fast`).

    budget : int
        The most work the search spends, in closest-point queries per model and per normal tried
        (twice as much without an ``outward`` hint); a field lookup counts as
        :data:`~tactrec.engine.LOOKUP_COST` of a query.  More: deeper tiers on hard touches,
        slower; a search that stops on it says so (``settled`` false).
    exhaustive : bool
        Search every vertex of every mesh at every 30 degrees, without ranking or pruning (the
        reference the tests and ``tactrec bench scale-exhaustive`` compare against; far slower).
    refine : int
        Poses a model refines on exact distances per tier (and seeds of the grids about a stall:
        twice as many).  More: fewer poses lost between the cheap scores and the fit, slower.
    ratio : float
        A model is refined when its cheap score lies within ``ratio`` times the best error so
        far; beyond it, it waits (deferred, not ruled out).  Also how far ahead of every other
        model the best must be to stop the search as clear.  At least 1.
    floor : float
        The mean distance of a fit of noise-free data, per unit of the touch's radius: the
        resolution below which two fits are one (:func:`tactrec.probability.resolution`).  Raise
        it for a sensor or scans coarser than 0.1% of a touch's radius.
    """

    budget: int = 300_000
    exhaustive: bool = False
    refine: int = 8
    ratio: float = 3.0
    floor: float = 1e-3

    # the schedule's constants, alike in shape by design: one ClassVar each, with the reason for its value

    #: frames tiers keep the best vertex of each grid cell a quarter of the touch's radius across
    #: (radius / spread), so that the places they pose are distinct
    spread: ClassVar[float] = 4.0
    #: points a curve the cheap stage's exact steps are taken on (its screen on the field: points a
    #: curve per :attr:`screen_stages`); refinement takes three times as many, the polish all
    coarse_points: ClassVar[int] = 5
    #: Gauss-Newton steps of a frames tier's cheap stage (after the first, the best eighth go on)
    cheap_steps: ClassVar[int] = 2
    #: at least this many of a frames tier's poses go past the cheap stage's first step
    screen: ClassVar[int] = 96
    #: exact steps of a refinement, accelerated (most poses stop on the tolerance far earlier)
    iterations: ClassVar[int] = 20
    #: models whose best pose takes the final polish, and the grids' models about a stall at the end
    polish: ClassVar[int] = 3
    #: the final polish's exact steps on all points
    polish_iterations: ClassVar[int] = 10
    #: below this ``|k1 - k2|`` (per unit of the touch's radius) the principal directions are not
    #: defined, and a frames tier turns the data every 30 degrees instead of posing them by the frames
    umbilic: ClassVar[float] = 0.05
    #: standard errors of a fit within which a best error above the fit limit may still be a fit
    #: (:attr:`tactrec.methods.fast_state.State.plausible`)
    within: ClassVar[float] = 3.0
    #: a pose's steps stop once no point moves by more than this fraction of the data's reach
    tolerance: ClassVar[float] = 1e-5
    #: past steps each accelerated step extrapolates from (Anderson acceleration,
    #: :mod:`tactrec.registration.anderson`): on a scan's facets a plain step slides a weakly held
    #: pose a few per cent of the way, for a hundred steps
    history: ClassVar[int] = 3
    #: a closed-form surface's table rows nearest in curvature that are refined
    candidates: ClassVar[int] = closedform_fast.DEFAULTS["candidates"]
    #: a field tier's grid cell, per unit of the touch's radius: places lie about as far apart as a
    #: rotation step moves the curves' ends
    screen_step: ClassVar[float] = 0.17
    #: the field screen's stages: rotations about the normal, points a curve, share of the places kept
    screen_stages: ClassVar[tuple] = ((36, 2, 0.05), (72, 4, 1.0))
    #: hypotheses of a field screen that take the field steps
    screen_keep: ClassVar[int] = 96
    #: places an indexed tier's first round screens (catalogue-wide; each later round twice as many):
    #: the index's ranking puts the true place of most touches among the first few thousand
    index_round: ClassVar[int] = 2048
    #: places of a model the index cannot tell from a fit's (its best place reads within the fit's
    #: band: :meth:`~tactrec.methods.fast_index.IndexedTier.twins`) screened before the search stops,
    #: its own best by the index: a model whose places all rank behind another's that fits would
    #: never be posed (two parts sharing a face, spheres of 30 and 31 mm)
    index_floor: ClassVar[int] = 8
    #: in an indexed round, hypotheses a model keeps for the field steps per place it screens (at
    #: most ``screen_keep``): a model with a few places in a round takes a few hypotheses, not 96
    index_keep: ClassVar[int] = 4
    #: Gauss-Newton steps on the field of each hypothesis kept
    field_steps: ClassVar[int] = 6
    #: degrees between the tilted normals (and the directions of a cell's normals that make places
    #: of their own): about the screen's reach from a normal that is off
    tilt_step: ClassVar[float] = 20.0
    #: the grid about a stall: seeds (the pose and its best alternative), values of each of the six
    #: turns and shifts, and its span, degrees and per unit of the touch's radius (the exact steps'
    #: basin on a scan's facets is about 2 degrees and 0.2 mm)
    hop_seeds: ClassVar[int] = 2
    hop_steps: ClassVar[int] = 3
    hop_angle: ClassVar[float] = 3.0
    hop_shift: ClassVar[float] = 0.02

    def __post_init__(self):
        for name, least in (("budget", 1), ("refine", 1)):
            value = getattr(self, name)
            self._check(name, isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= least,
                        f"a whole number >= {least}")
        self._check("exhaustive", isinstance(self.exhaustive, (bool, np.bool_)), "true or false")
        for name in ("ratio", "floor"):
            value = getattr(self, name)
            self._check(name, isinstance(value, (int, float, np.number)) and np.isfinite(value) and value > 0,
                        "a positive number")
        self._check("ratio", self.ratio >= 1.0, "at least 1")

    @property
    def tiers(self) -> tuple:
        """The schedule: :data:`TIERS`, or :data:`EXHAUSTIVE` for the exhaustive reference."""
        return EXHAUSTIVE if self.exhaustive else TIERS
