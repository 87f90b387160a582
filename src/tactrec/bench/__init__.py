"""Reproductions of the paper's experiments and benchmarks (``tactrec bench NAME``).

:data:`BENCHMARKS` maps a name to a function ``run(*, out, instances, seed,
jobs, quiet) -> dict`` that writes its JSON table and plots into ``out`` and
returns the table.  A new benchmark adds its module and one line here.
"""

from __future__ import annotations

from typing import Callable

from . import (baselines, calibration, cold_start, fast_vs_paper, field, fit_limit, kernels, multi_touch, open_world,
               paper_closedform, paper_example, paper_fig11, paper_mesh, paper_steps, paper_table5, paper_table6, scale,
               search_limits, sensor, serve)

__all__ = ["BENCHMARKS"]

BENCHMARKS: dict[str, Callable[..., dict]] = {
    "paper-table2": paper_closedform.run_table2,
    "paper-table3": paper_closedform.run_table3,
    "paper-example": paper_example.run,
    "paper-table4": paper_mesh.run_table4,
    "paper-fig11": paper_fig11.run_fig11,
    "paper-table5": paper_table5.run,
    "paper-table6": paper_table6.run,
    "paper-steps": paper_steps.run,
    "fast-vs-paper": fast_vs_paper.run,
    "scale": scale.run_scale,
    "scale-exhaustive": scale.run_exhaustive,
    "baselines": baselines.run,
    "fit-limit": fit_limit.run,
    "kernels": kernels.run,
    "cold-start": cold_start.run,
    "search-limits": search_limits.run,
    "calibration": calibration.run,
    "multi-touch": multi_touch.run,
    "field": field.run,
    "open-world": open_world.run,
    "serve": serve.run,
    "sensor": sensor.run,
}
