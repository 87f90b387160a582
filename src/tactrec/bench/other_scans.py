"""Free-form meshes from other sources than YCB (``--scans other``): unseen objects for the benches.

tactrec is scored on objects it has never seen, so its search is measured
on meshes that were never used to tune it: scans and sculpted models that
ship inside two packages on PyPI, the Stanford bunny and dragon and other
models of ``genesis-world`` and the dog skeleton and skin of ``dm-control``
(both Apache-2.0; the Stanford models are for research use).  Their wheels
are fetched once with ``pip download`` (no dependencies, nothing installed)
into the cache folder (:func:`tactrec.database.cache_folder`), and only the
listed files are read from them.

Each model is scaled so that its bounding box's diagonal is the size listed
(55-105 mm, the span of the paper's scans), in millimetres.  Nothing in the
method is tuned on them: they stand in for the scans tactrec will meet.
:func:`other_database` also builds the machined parts of
:mod:`tactrec.bench.cad_parts` (``--scans cad``), made by code.
"""

from __future__ import annotations

import functools
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np

from ..errors import InputError
from .cad_parts import CAD

__all__ = ["SOURCES", "OTHER", "fetch", "other_database"]

#: the wheels the meshes come from: name, version
WHEELS = {"genesis-world": "1.4.5", "dm-control": "1.0.50"}

#: (name, package, path inside its wheel, size in mm: the bounding box's diagonal)
SOURCES = (
    ("bunny", "genesis-world", "genesis/assets/meshes/bunny.obj", 100.0),
    ("dragon", "genesis-world", "genesis/assets/meshes/dragon/dragon.obj", 105.0),
    ("duck", "genesis-world", "genesis/assets/meshes/duck.obj", 80.0),
    ("bolt", "genesis-world", "genesis/assets/meshes/bolt_nut/bolt.stl", 90.0),
    ("nut", "genesis-world", "genesis/assets/meshes/bolt_nut/nut.stl", 60.0),
    ("worm", "genesis-world", "genesis/assets/meshes/worm/worm.obj", 75.0),
    ("dog", "dm-control", "dm_control/suite/dog_assets/SKINbody.stl", 105.0),
    ("pelvis", "dm-control", "dm_control/suite/dog_assets/BONEPelvis.stl", 85.0),
    ("sacrum", "dm-control", "dm_control/suite/dog_assets/BONESacrum.stl", 60.0),
    ("scapula", "dm-control", "dm_control/suite/dog_assets/BONEScapula_L.stl", 80.0),
    ("femur", "dm-control", "dm_control/suite/dog_assets/BONEFemoris_L.stl", 95.0),
    ("humerus", "dm-control", "dm_control/suite/dog_assets/BONEhumerus_L.stl", 90.0),
    ("atlas", "dm-control", "dm_control/suite/dog_assets/BONEC_1.stl", 65.0),
    ("lumbar", "dm-control", "dm_control/suite/dog_assets/BONEL_3.stl", 55.0),
)
#: their names, in order
OTHER = tuple(name for name, *_ in SOURCES)


def _folder() -> Path:
    from ..database import cache_folder

    return cache_folder() / "other-scans"


def fetch(folder: Path | None = None) -> dict[str, Path]:
    """The mesh files of :data:`SOURCES`, fetched and extracted once into ``folder``."""
    folder = Path(folder or _folder())
    files = folder / "files"
    out = {name: files / f"{name}{Path(path).suffix}" for name, _, path, _ in SOURCES}
    if all(p.is_file() for p in out.values()):
        return out
    wheels = folder / "wheels"
    wheels.mkdir(parents=True, exist_ok=True)
    files.mkdir(parents=True, exist_ok=True)
    for package, version in WHEELS.items():
        stem = package.replace("-", "_")
        if not list(wheels.glob(f"{stem}-{version}-*.whl")):
            done = subprocess.run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary",
                                   ":all:", "-d", str(wheels), f"{package}=={version}"], capture_output=True, text=True)
            if done.returncode != 0:
                raise InputError(f"cannot fetch {package}=={version} from the package index "
                                 f"({done.stderr.strip().splitlines()[-1] if done.stderr.strip() else 'pip failed'})",
                                 wheels)
    for name, package, path, _ in SOURCES:
        if out[name].is_file():
            continue
        wheel = next(wheels.glob(f"{package.replace('-', '_')}-{WHEELS[package]}-*.whl"))
        with zipfile.ZipFile(wheel) as archive:
            blob = archive.read(path)
        partial = out[name].with_suffix(out[name].suffix + ".part")
        partial.write_bytes(blob)
        partial.replace(out[name])
    return out


def _part(name: str):
    """The CAD part ``name`` as a mesh model (mm), named by its geometry's hash."""
    import hashlib

    from ..surfaces.mesh import MeshModel
    from .cad_parts import part_mesh

    vertices, faces = part_mesh(name)
    digest = hashlib.sha256(vertices.tobytes() + faces.tobytes()).hexdigest()
    return MeshModel(vertices, faces, name=name, units="mm", source=f"<cad part {name}>", source_hash=digest)


@functools.lru_cache(maxsize=1)
def other_database(names: tuple[str, ...] = OTHER):
    """The meshes ``names`` of :data:`SOURCES`, each scaled to its size in millimetres, with their
    tables, kept for the rest of this process."""
    import trimesh

    from ..database import Database, model_entry
    from ..surfaces.mesh import MeshModel

    sizes = {name: size for name, _, _, size in SOURCES}
    files = fetch() if set(names) & set(sizes) else {}
    entries = []
    for name in names:
        if name in CAD:
            entries.append(model_entry(_part(name)))
            continue
        if name not in sizes:
            raise InputError(f"no such scan among the other sources; choose from {', '.join(OTHER)}", name)
        raw = trimesh.load(files[name], force="mesh", process=False)
        diagonal = float(np.linalg.norm(np.ptp(np.asarray(raw.vertices), axis=0)))
        model = MeshModel.from_file(files[name], units="mm", name=name)
        model = MeshModel(model.vertices * (sizes[name] / diagonal), model.faces, name=name, units="mm",
                          source=model.source, source_hash=model.source_hash, scale=sizes[name] / diagonal,
                          cleanup=model.cleanup)
        entries.append(model_entry(model))
    return Database(entries)
