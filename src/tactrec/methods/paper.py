"""Method ``paper``: the paper's own algorithm, model by model (Sections 3.2, 4.2, 5.3).

Each model is registered on its own: the lookup within ``delta`` (eq. 7; a
model without a candidate is rejected, "NC"), then steepest descent on
``E(u, v, phi)`` on a closed-form surface (:mod:`tactrec.registration.closedform_paper`)
or the greedy walk over eq. 15's plane sections on a mesh
(:mod:`tactrec.registration.mesh_paper`).  Without an ``outward`` hint both
normals are tried and the better registration kept.

The paper fits "a parabola to a few data points on the curve and around p"
(Section 3.1.1) without saying how few: ``parabola_points`` reads it as the
``N`` points each side of ``p``; by default the method takes the touch's
estimate as every method gets it (:func:`tactrec.estimation.estimate`, each
curve's window chosen from its own noise).  ``tactrec bench paper-steps``
measures the readings step by step.  No fixed count reproduces the paper
throughout: 3 points each side matches the mesh tables' scale on noise-free
touches of fine scans (P3), but follows the noise of the paper's
closed-form and Table 6 touches and falls inside one facet of a coarse
scan, so it is an option, not the default.

A touch with a round tip (:mod:`tactrec.tip`): the lookup takes the
corrected curvatures and the steps take the curves moved onto the surface on
the side tried (:meth:`tactrec.features.Touch.on_surface`), part (a) of the
rule.  Part (b) the paper's steps do not allow: eq. 15 compares the data
with plane sections of the mesh point by point, and the steepest descent on
``E(u, v, phi)`` measures eq. 11 at the data, so both measure the moved
points rather than the centres against the offset surface, and the error
they report carries what the move left (about ``r`` times the error of the
local fit's normals, largest at the curves' ends).  The probabilities are
measured as for every method, from the centres against the offset.
"""

from __future__ import annotations

import dataclasses

from ..estimation import estimate
from ..registration import closedform_paper, mesh_paper
from ..registration.result import Outcome, Registration
from .base import NOT_SEARCHED, Config, SearchOutcome
from .common import best_of_orientations, in_model_units

__all__ = ["PaperMethod", "PaperConfig"]


@dataclasses.dataclass(frozen=True)
class PaperConfig(Config):
    """Options of the ``paper`` method.

    delta : float or None
        Lookup tolerance on ``(k1, k2)``, 1/model units (eq. 7); None: 0.2 on closed-form
        surfaces, the paper's 0.03 /mm in a mesh's units.
    phi_samples, bisections, max_iterations
        The initial-phi scan, its bisections and the steepest-descent steps (Section 4.2).
    phi_step, max_steps
        The rotation step in degrees and the greedy walk's longest run on a mesh (Section 5.3).
    parabola_points : int or None
        The estimate from the paper's parabola fitted to this many points each side of ``p``
        (Section 3.1.1); None: the touch's own estimate.
    """

    delta: float | None = None
    phi_samples: int = closedform_paper.DEFAULTS["phi_samples"]
    bisections: int = closedform_paper.DEFAULTS["bisections"]
    max_iterations: int = closedform_paper.DEFAULTS["max_iterations"]
    phi_step: float = mesh_paper.DEFAULTS["phi_step"]
    max_steps: int = mesh_paper.DEFAULTS["max_steps"]
    parabola_points: int | None = None

    def __post_init__(self):
        self._check("delta", self.delta is None or self.delta > 0, "positive")
        for name in ("phi_samples", "bisections", "max_iterations", "max_steps"):
            self._check(name, isinstance(getattr(self, name), int) and getattr(self, name) >= 1, "a whole number >= 1")
        self._check("phi_step", 0 < self.phi_step <= 180, "in (0, 180] degrees")
        self._check("parabola_points", self.parabola_points is None
                    or (isinstance(self.parabola_points, int) and self.parabola_points >= 2), "a whole number >= 2")

    def geometry(self, data):
        """The :class:`~tactrec.estimation.LocalGeometry` this reading gives for tactile ``data``
        (None: the touch's own estimate)."""
        if self.parabola_points is None:
            return None
        return estimate(data, window=self.parabola_points, degree=2)


def _register(entry, touch, config: PaperConfig) -> Registration:
    model = entry.model
    touch = in_model_units(touch, model)
    if model.kind == "mesh":
        def one(g, sign):
            s = touch.on_surface(sign)
            return mesh_paper.register(model, entry.table, g, s.points, curves=s.curves, delta=config.delta,
                                       phi_step=config.phi_step, max_steps=config.max_steps)
    else:
        def one(g, sign):
            return closedform_paper.register(model, entry.table, g, touch.on_surface(sign).points,
                                             delta=closedform_paper.DEFAULTS["delta"] if config.delta is None
                                             else config.delta, phi_samples=config.phi_samples,
                                             bisections=config.bisections, max_iterations=config.max_iterations)
    return best_of_orientations(one, touch, model.name)


def _stage(held, indices, touch, config) -> list[Registration]:
    return [_register(held.entries[i], touch, config) for i in indices]


# a twin of methods/fast.py's FastMethod by design: both are the hooks of the Method protocol (.base)
class PaperMethod:
    """The paper's method (see the module text)."""

    name = "paper"
    scores_context = False
    uses_engine = False
    uses_index = False
    Config = PaperConfig

    def configure(self, **options) -> PaperConfig:
        return PaperConfig.from_options(self.name, options)

    def prepare(self, model) -> None:
        """Nothing beyond the lookup table, which the database holds."""

    def search(self, touch, models, config: PaperConfig, runner, *, among=None, budget=None,
               index=None) -> SearchOutcome:
        """Every model at ``among`` (all when None) searched in full: the paper's method has no budget."""
        own = config.geometry(touch.data)          # this reading's estimate, once for every model
        if own is not None:
            touch = touch.with_estimate(own)
        chosen = range(len(models)) if among is None else sorted(among)
        found = dict(zip(chosen, runner.map(_stage, chosen, touch, config)))
        return SearchOutcome([found[i] if i in found
                              else Registration.unfitted(e.name, NOT_SEARCHED, Outcome.NOT_SEARCHED)
                              for i, e in enumerate(models)])

    def refit(self, touch, models, config: PaperConfig, runner, outcome: SearchOutcome) -> SearchOutcome:
        """The paper's registration has no step that starts from a given pose: ``touch`` is searched
        in full again, on the models ``outcome`` searched, its work added."""
        among = [i for i, r in enumerate(outcome.ranking) if r.outcome is not Outcome.NOT_SEARCHED]
        again = self.search(touch, models, config, runner, among=among)
        return dataclasses.replace(again, work=again.work + outcome.work)
