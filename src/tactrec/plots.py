"""Pictures: a model with registered curves, and Fig. 8-style location plots.

Importing :mod:`tactrec` never imports matplotlib; these functions do, with
the non-interactive Agg backend.  Each takes an ``ax`` (or makes one) and
returns it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["plot_registration", "plot_uv_locations", "save_figure", "pyplot"]


def pyplot():
    """matplotlib's pyplot on the Agg backend (no display), imported when a figure is first drawn."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_registration(model, curves_model_frame, *, location=None, ax=None, title=None, resolution: int = 60):
    """Draw a model (closed-form surface or mesh) and data curves already mapped into its frame.

    Parameters
    ----------
    model : ClosedFormSurface or MeshModel
    curves_model_frame : list of (n_i, 3) arrays
    location : (3,) array, optional
        The registered contact point.
    """
    plt = pyplot()
    if ax is None:
        fig = plt.figure(figsize=(6, 5))
        ax = fig.add_subplot(projection="3d")
    pts = np.zeros((0, 3))
    if hasattr(model, "domain_u"):
        uu, vv = np.meshgrid(np.linspace(model.domain_u.lo, model.domain_u.hi, resolution),
                             np.linspace(model.domain_v.lo, model.domain_v.hi, resolution), indexing="ij")
        pts = model.evaluate(uu, vv)
        ax.plot_surface(pts[..., 0], pts[..., 1], pts[..., 2], color="0.8", alpha=0.35, linewidth=0,
                        antialiased=True, shade=True)
    elif hasattr(model, "faces"):
        pts = model.vertices
        ax.plot_trisurf(pts[:, 0], pts[:, 1], pts[:, 2], triangles=model.faces, color="0.8", alpha=0.3,
                        linewidth=0, antialiased=True, shade=True)
    colours = ["tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple"]
    for i, c in enumerate(curves_model_frame):
        ax.plot(c[:, 0], c[:, 1], c[:, 2], color=colours[i % len(colours)], linewidth=2.0, zorder=10)
    if location is not None:
        ax.scatter(*np.asarray(location), color="k", s=30, zorder=11)
    try:
        ax.set_box_aspect(np.ptp(np.concatenate([pts.reshape(-1, 3)] + list(curves_model_frame)), axis=0) + 1e-9)
    except Exception:  # older matplotlib or no surface drawn
        pass
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_zlabel("z")
    if title:
        ax.set_title(title)
    return ax


def plot_uv_locations(model, true_uv, estimated_uv, *, ax=None, title=None):
    """Fig. 8: true contact locations (dots) and estimates (crosses) in the (u, v) domain."""
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    true_uv = np.asarray(true_uv, dtype=float).reshape(-1, 2)
    estimated_uv = np.asarray(estimated_uv, dtype=float).reshape(-1, 2)
    ax.scatter(true_uv[:, 0], true_uv[:, 1], s=28, facecolors="none", edgecolors="tab:blue", label="true p")
    ax.scatter(estimated_uv[:, 0], estimated_uv[:, 1], marker="x", s=28, color="tab:red", label="estimated p*")
    ax.set_xlim(model.domain_u.lo, model.domain_u.hi)
    ax.set_ylim(model.domain_v.lo, model.domain_v.hi)
    ax.set_xlabel("u")
    ax.set_ylabel("v")
    ax.set_title(title or model.name)
    return ax


def save_figure(ax_or_fig, path) -> None:
    """Save the figure of ``ax_or_fig`` as PNG, atomically, and close it."""
    import io

    from .io.atomic import write_bytes_atomic

    plt = pyplot()
    fig = getattr(ax_or_fig, "figure", ax_or_fig)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    write_bytes_atomic(path, buf.getvalue())
