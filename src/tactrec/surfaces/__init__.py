"""Surface models: closed-form (TOML) and, by file suffix, other kinds.

A new kind of model needs its own module and one line in :data:`LOADERS`.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Callable

from ..errors import InputError
from .base import SiteFrame, SurfaceModel, TableSamples
from .closedform import ClosedFormSurface
from .mesh import MESH_SUFFIXES, MeshModel

__all__ = [
    "SurfaceModel", "TableSamples", "SiteFrame", "ClosedFormSurface", "MeshModel",
    "LOADERS", "KINDS", "BUILTIN_SETS", "load_model", "builtin_names", "builtin_path", "resolve_models",
]

def _load_toml(path: Path, **_mesh_options) -> ClosedFormSurface:
    """A TOML surface declares its own units; mesh options do not apply."""
    return ClosedFormSurface.from_file(path)


#: file suffix -> loader taking a path (and the mesh options ``units``, ``scale``)
LOADERS: dict[str, Callable[..., SurfaceModel]] = {
    ".toml": _load_toml,
    **{suffix: MeshModel.from_file for suffix in MESH_SUFFIXES},
}

#: model kind -> class with ``from_store(arrays, name=, source=)`` (databases)
KINDS: dict[str, type] = {
    ClosedFormSurface.kind: ClosedFormSurface,
    MeshModel.kind: MeshModel,
}

#: named sets of built-in models
BUILTIN_SETS: dict[str, tuple[str, ...]] = {
    "paper-table1": ("ellipsoid", "elliptic-paraboloid", "monkey-saddle", "crossed-trough"),
    "paper-objects": ("cylinder-50", "cylinder-94", "elliptic-cylinder", "sphere-33"),
}
BUILTIN_SETS["closed-form"] = BUILTIN_SETS["paper-table1"] + BUILTIN_SETS["paper-objects"]
BUILTIN_SETS["builtin"] = BUILTIN_SETS["closed-form"]


def _builtin_dir():
    return resources.files("tactrec.surfaces") / "builtin"


def builtin_names() -> list[str]:
    """Names of the built-in models."""
    return sorted(p.name[: -len(".toml")] for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))


def builtin_path(name: str) -> Path:
    """Path of a built-in model's file."""
    path = Path(str(_builtin_dir() / f"{name}.toml"))
    if not path.is_file():
        raise InputError(f"no built-in model named {name!r} (built-ins: {', '.join(builtin_names())})", name)
    return path


def load_model(spec: str | os.PathLike, *, units: str | None = None, scale: float | None = None) -> SurfaceModel:
    """Load a model from a file, or a built-in model by name.

    ``units`` (the file's) and ``scale`` (a factor on its coordinates) apply
    to mesh files.  Raises :class:`InputError` (one line naming the file) on
    any problem.
    """
    path = Path(spec)
    if not path.exists() and isinstance(spec, str) and spec in builtin_names():
        path = builtin_path(spec)
    if not path.exists():
        raise InputError(f"no such file or built-in model (built-ins: {', '.join(builtin_names())})", spec)
    loader = LOADERS.get(path.suffix.lower())
    if loader is None:
        raise InputError(f"unsupported model format {path.suffix!r}; expected one of {', '.join(LOADERS)}", path)
    return loader(path, units=units, scale=scale)


def resolve_models(specs) -> list[Path]:
    """Expand model arguments (files, built-in names, set names) into file paths."""
    out: list[Path] = []
    for spec in specs:
        if isinstance(spec, str) and spec in BUILTIN_SETS and not Path(spec).exists():
            out.extend(builtin_path(n) for n in BUILTIN_SETS[spec])
        elif isinstance(spec, str) and not Path(spec).exists() and spec in builtin_names():
            out.append(builtin_path(spec))
        else:
            out.append(Path(spec))
    return out
