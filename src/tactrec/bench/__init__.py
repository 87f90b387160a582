"""Reproductions of the paper's experiments and benchmarks (``tactrec bench NAME``).

:data:`BENCHMARKS` maps a name to a :class:`Benchmark`: where its function ``run(*, out,
instances, seed, jobs, quiet) -> dict`` lives (it writes its JSON table and plots into
``out`` and returns the table) and one line saying what it measures, which ``tactrec bench
--help`` lists.  A new benchmark adds its module and one line here.  The modules are imported
when a benchmark runs, not when the command line is parsed.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Callable

__all__ = ["BENCHMARKS", "Benchmark"]


@dataclasses.dataclass(frozen=True)
class Benchmark:
    """One benchmark: ``function`` in ``tactrec.bench.<module>``, and what it measures."""

    module: str
    function: str
    summary: str

    @property
    def run(self) -> Callable[..., dict]:
        return getattr(importlib.import_module(f"{__name__}.{self.module}"), self.function)


BENCHMARKS: dict[str, Benchmark] = {
    "paper-example": Benchmark("paper_example", "run", "Section 4.3.1: the worked estimate on the elliptic paraboloid"),
    "paper-table2": Benchmark("paper_closedform", "run_table2", "P1, Table 2: touches of each closed-form surface registered onto it"),
    "paper-table3": Benchmark("paper_closedform", "run_table3", "P2, Table 3 and Fig. 8: the same touches recognised among the four surfaces"),
    "paper-table4": Benchmark("paper_mesh", "run_table4", "P4, Table 4: lookup tables built on the ten YCB scans"),
    "paper-fig11": Benchmark("paper_fig11", "run_fig11", "P3, Fig. 11: recognition on ten YCB scans, swept over noise, length, angle"),
    "paper-table5": Benchmark("paper_table5", "run", "P5, Table 5: the four closed-form objects of Fig. 13"),
    "paper-table6": Benchmark("paper_table6", "run", "P5, Table 6: every scan's touch registered onto every scan"),
    "paper-steps": Benchmark("paper_steps", "run", "the paper method's steps one at a time, on P3's touches"),
    "fast-vs-paper": Benchmark("fast_vs_paper", "run", "fast against paper on the same P3 and hard touches, in one run"),
    "scale": Benchmark("scale", "run_scale", "recognition among all 78 YCB scans: top-1, top-3, time"),
    "scale-out": Benchmark("scale_out", "run", "1,078 models (78 scans, 1,000 generated): top-1, top-3, near twins, time, memory"),
    "scale-exhaustive": Benchmark("scale", "run_exhaustive", "among 78 scans, fast against an exhaustive search"),
    "baselines": Benchmark("baselines", "run", "Open3D's registrations on the same touches (make install-baselines)"),
    "fit-limit": Benchmark("fit_limit", "run", "which misses the best-fit rule itself makes"),
    "kernels": Benchmark("kernels", "run", "the same touches under two OpenBLAS kernels: the same answers"),
    "cold-start": Benchmark("cold_start", "run", "tactrec recognize in a new process per touch"),
    "search-limits": Benchmark("search_limits", "run", "where the index ranks the true place; how far the refinement reaches"),
    "calibration": Benchmark("calibration", "run", "confidence against the truth on single touches"),
    "multi-touch": Benchmark("multi_touch", "run", "sessions: next's touches against random ones"),
    "field": Benchmark("field", "run", "each mesh's distance field against exact distances"),
    "open-world": Benchmark("open_world", "run", "touches and sessions of scans left out of the database"),
    "serve": Benchmark("serve", "run", "what a request to tactrec serve costs beyond its recognition"),
    "sensor": Benchmark("sensor", "run", "touches as sensors record them: tip, outliers, miss, spacing, jitter"),
    "patch": Benchmark("patch", "run", "touches as patches of 2-10 mm: accuracy beside the fit-limit ceiling, contact, time"),
    "contacts": Benchmark("contacts", "run", "sessions of single contacts: how many it takes to be right at >= 0.95"),
    "contact-search": Benchmark("contact_search", "run", "touches of 3-5 contacts: how often the search rejects the touched scan"),
    "tacloc": Benchmark("tacloc", "run", "TacLoc's registration (tacreg, installed apart) on patch's patches, beside fast"),
    "viewer": Benchmark("viewer", "run", "tactrec show's page: its size, and the time a browser takes to draw it"),
    "answers": Benchmark("answers", "run", "the JSON of 50 seeded recognitions and 5 sessions, and their digests"),
}
