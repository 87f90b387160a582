"""Model databases: everything recognition needs, stored safely.

A database is a folder::

    DB/index.json              format, version, one entry per model
    DB/<name>-<hash>.npz       the model's arrays and its lookup table
    DB/chance.json             the null model of chance fits, where fitted (``tactrec calibrate``)

Arrays are plain ``.npz`` files read with ``allow_pickle=False``; each entry
records the SHA-256 of its source file (a changed source is rebuilt, an
unchanged one reused) and of its ``.npz`` (a damaged file is reported, not
used).  Every file is written atomically.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
import os
import re
import sys
import time
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .errors import InputError
from .io.atomic import atomic_write, write_text_atomic
from .recognition import ModelEntry
from .surfaces import KINDS, load_model, resolve_models
from .tables import CurvatureTable

__all__ = ["Database", "BuildReport", "build_database", "load_database", "build_entries", "file_sha256",
           "open_models", "cache_folder", "cached_database", "model_entry"]

FORMAT = "tactrec-db"
VERSION = 3            # 2: meshes store their fitted normals; 3: and their distance fields (the engine's screen)
#: bump when table construction changes, so that old tables are rebuilt
TABLE_VERSION = 2
#: bump when what a model stores besides its table changes, so that a build redoes it (a database
#: of an older one still loads: what it lacks is made on first use); 2: a mesh's outer field; 3: its
#: places' rings (the index of places: :mod:`tactrec.index`)
STORE_VERSION = 3
#: seconds between two writes of the index while a build is under way
INDEX_EVERY = 10.0


@dataclasses.dataclass
class Database:
    """Models with their tables, as used by :func:`tactrec.recognition.recognize`."""

    entries: list[ModelEntry]
    path: Path | None = None
    chance: object = None          # its null model of chance fits (tactrec.chance), where fitted on these models

    def __iter__(self):
        return iter(self.entries)

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def names(self) -> list[str]:
        return [e.name for e in self.entries]

    def get(self, name: str) -> ModelEntry:
        for e in self.entries:
            if e.name == name:
                return e
        raise KeyError(name)


@dataclasses.dataclass(frozen=True)
class BuildReport:
    path: Path
    built: list[str]
    reused: list[str]
    removed: list[str]


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _progress(iterable, *, total: int, desc: str, quiet: bool):
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, unit="model", file=sys.stderr,
                disable=quiet or not sys.stderr.isatty(), leave=False)


def model_entry(model) -> ModelEntry:
    """A model and its lookup table (the paper's, Section 3.2.1 or 5.2), built now."""
    return ModelEntry(model, CurvatureTable(model.table_samples()))


def build_entries(models: Iterable, *, quiet: bool = True, units: str | None = None,
                  scale: float | None = None) -> Database:
    """Load models (paths, built-in names or set names) and build their tables in memory.

    ``units`` and ``scale`` apply to mesh files (see :func:`tactrec.surfaces.load_model`).
    """
    sources = resolve_models(models)
    entries = [model_entry(load_model(src, units=units, scale=scale))
               for src in _progress(sources, total=len(sources), desc="models", quiet=quiet)]
    _check_unique([e.name for e in entries], [src.path for src in sources])
    return Database(entries)


def _check_unique(names: Sequence[str], paths: Sequence) -> None:
    seen: dict[str, object] = {}
    for name, path in zip(names, paths):
        if name in seen:
            raise InputError(f"two models are named {name!r} (also {seen[name]})", path)
        seen[name] = path


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)[:80] or "model"


def _read_index(db: Path, *, partial: bool = False) -> dict:
    index_path = db / "index.json"
    if not db.exists():
        raise InputError("no such database", db)
    if not db.is_dir():
        raise InputError("a database is a folder holding index.json", db)
    if not index_path.exists():
        raise InputError("not a tactrec database (no index.json)", db)
    try:
        index = json.loads(index_path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"corrupted database index ({exc.__class__.__name__})", index_path) from None
    if not isinstance(index, dict) or index.get("format") != FORMAT or not isinstance(index.get("models"), list):
        raise InputError("corrupted database index (not a tactrec database)", index_path)
    if index.get("complete", True) is not True and not partial:
        raise InputError("a build of this database was stopped before it ended; run the same 'tactrec build' "
                         "again to finish it (what was built is kept)", index_path)
    if index.get("version") != VERSION:
        raise InputError(f"database format version {index.get('version')!r}, this tactrec reads version {VERSION}: "
                         "rebuild it with 'tactrec build'", index_path)
    for item in index["models"]:
        if not isinstance(item, dict) or not all(isinstance(item.get(k), str) for k in
                                                 ("name", "kind", "file", "source", "source_sha256", "file_sha256")):
            raise InputError("corrupted database index (a model entry is incomplete)", index_path)
    return index


def _load_entry(db: Path, item: dict, *, fields: bool = True) -> ModelEntry:
    """The model of the index entry ``item`` of the database ``db``, checked against its checksum;
    without ``fields``, a mesh keeps none of its distance fields' bytes
    (:class:`~tactrec.surfaces.mesh_field.FieldsElsewhere`)."""
    path = db / item["file"]
    if Path(item["file"]).name != item["file"]:
        raise InputError("corrupted database index (bad file name)", db / "index.json")
    if not path.is_file():
        raise InputError("missing from the database; rebuild it", path)
    blob = path.read_bytes()
    if hashlib.sha256(blob).hexdigest() != item["file_sha256"]:
        raise InputError("corrupted database file (checksum mismatch); rebuild it", path)
    kind = KINDS.get(item["kind"])
    if kind is None:
        raise InputError(f"unknown model kind {item['kind']!r}", path)
    try:
        # the arrays are read when used (a mesh's distance field on its first search); the file's
        # checksum was checked above, so what is read later is what was written
        arrays = np.load(io.BytesIO(blob), allow_pickle=False)
        model = kind.from_store(arrays, name=item["name"], source=item["source"])
        table = CurvatureTable.from_arrays(arrays)
    except InputError as exc:
        raise InputError(f"corrupted database file ({exc.reason})", path) from None
    except (ValueError, KeyError, OSError, EOFError) as exc:
        raise InputError(f"corrupted database file ({exc.__class__.__name__}: {exc})", path) from None
    if getattr(model, "_stored_field", None) is not None:
        from .surfaces.mesh_field import FieldsElsewhere, FieldsOnDisk

        # the fields are read from the file when used, not kept compressed in memory
        model._stored_field = FieldsOnDisk(path, arrays.files) if fields else FieldsElsewhere(arrays, path)
    return ModelEntry(model, table, (str(db), dict(item)))


def load_database(path: str | os.PathLike, *, warn=None, fields: bool = True) -> Database:
    """Load a database built by :func:`build_database`.

    ``warn`` (a callable taking one line) is told about models whose source
    file has changed since the database was built.  Without ``fields`` the
    meshes' distance fields are not kept (a cluster's client: its workers
    read them, :mod:`tactrec.cluster`), and reading one is an error.
    """
    db = Path(path)
    index = _read_index(db)
    entries = []
    for item in index["models"]:
        entries.append(_load_entry(db, item, fields=fields))
        src = Path(item["source"])
        if warn is not None and not item.get("builtin") and src.is_file() and file_sha256(src) != item["source_sha256"]:
            warn(f"{src}: changed since the database was built; run 'tactrec build' to update {db}")
    if not entries:
        raise InputError("the database holds no models", db)
    from . import chance

    try:
        stored = chance.load(db)
    except InputError as exc:                 # optional: a damaged one is set aside, not the database
        if warn is not None:
            warn(f"{exc}; run 'tactrec calibrate --db {db}' again")
        stored = None
    if stored is not None and stored.key != chance.catalogue_key(entries):
        if warn is not None:
            warn(f"{db / chance.FILE}: fitted on other models; run 'tactrec calibrate --db {db}' again")
        stored = None
    return Database(entries, db, stored)


def _stored_blob(model, tips=()) -> tuple[bytes, int]:
    """A model's database file (its arrays and its table, compressed) and its table's rows; a mesh's
    with its outer field and the fields of its offsets by the tip radii ``tips``
    (:mod:`tactrec.surfaces.mesh_offset`)."""
    entry = model_entry(model)
    arrays = dict(model.to_store(), **entry.table.to_arrays())
    if model.kind == "mesh":
        from .surfaces.mesh_offset import offset_arrays, outer_arrays

        arrays.update(outer_arrays(model))
        if tips:
            arrays.update(offset_arrays(model, tips))
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue(), len(entry.table)


def _stored_of(held: tuple, k: int) -> tuple[bytes, int]:
    """:func:`_stored_blob` of model ``k`` of a build's worker, which holds ``(models, tips)``."""
    models, tips = held
    return _stored_blob(models[k], tips)


def _stored(models: list, todo: list[int], *, quiet: bool, tips=()):
    """``(k, blob, rows)`` of :func:`_stored_blob` for each model ``k`` of ``todo``, in order, as each is
    done: in two forked worker processes when there are two or more (a scan's distance field and
    tables take a second or two each), else here."""
    from .runner import Workers, can_fork

    bar = _progress(range(len(todo)), total=len(todo), desc="building", quiet=quiet)
    jobs = min(2, os.cpu_count() or 1, len(todo))
    try:
        if jobs < 2 or not can_fork():
            for k in todo:
                yield (k, *_stored_blob(models[k], tips))
                bar.update()
            return
        pool = Workers((models, tips), jobs)
        try:
            for k, found in zip(todo, pool.map(_stored_of, todo)):
                yield (k, *found)
                bar.update()
        finally:
            pool.close()
    finally:
        bar.close()


def _write_index(out: Path, items: list[dict], *, complete: bool) -> None:
    """The index of the entries ``items``; ``complete`` False while a build is under way, so that a
    build that is stopped leaves what it finished for the next build to reuse, and no database that
    passes for whole."""
    index = {"format": FORMAT, "version": VERSION, "models": items, **({} if complete else {"complete": False})}
    write_text_atomic(out / "index.json", json.dumps(index, indent=1) + "\n")


def build_database(models: Iterable, out: str | os.PathLike, *, quiet: bool = False, units: str | None = None,
                   scale: float | None = None, tips: Iterable[float] = (), cluster=None) -> BuildReport:
    """Build (or update) the database ``out`` from model files or built-in names.

    Models whose source file, options (``units``, ``scale`` of mesh files,
    ``tips``) and table builder are unchanged are reused; the others are
    rebuilt.  The database afterwards holds exactly ``models``.  ``tips``:
    radii of round tips (the meshes' units) whose offset fields each mesh
    stores (:mod:`tactrec.surfaces.mesh_offset`), so that touches of such a
    tip are searched without building them first.  With ``cluster``
    (:func:`tactrec.cluster.connect`) the models are built as tasks on its
    workers and written here as they come: the same files, to the byte.
    """
    tips = sorted({float(r) for r in tips})
    if not all(np.isfinite(r) and r > 0 for r in tips):
        raise InputError(f"a tip radius is a positive number (got {tips})", out)
    out = Path(out)
    sources = resolve_models(models)
    if not sources:
        raise InputError("no models given", out)
    old: dict[str, dict] = {}
    if (out / "index.json").exists():
        try:
            index = _read_index(out, partial=True)
            old = {item["name"]: item for item in index["models"]}
        except InputError:
            old = {}  # a broken database is rebuilt from scratch
    elif out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", out)
    built, reused = [], []
    models = [load_model(src, units=units, scale=scale) for src in sources]  # all checked before any write
    _check_unique([model.name for model in models], [src.path for src in sources])
    plans = []
    for src, model in zip(sources, models):
        sha = file_sha256(src.path)
        options = {"units": units if units is not None else src.units,
                   "scale": scale if scale is not None else src.scale} if model.kind == "mesh" else {}
        if tips and model.kind == "mesh":
            options["tips"] = tips
        prev = old.get(model.name)
        fresh = not (prev and prev["source_sha256"] == sha and prev.get("table_version") == TABLE_VERSION
                     and prev.get("store_version", 1) == STORE_VERSION
                     and prev.get("options", {}) == options
                     and (out / prev["file"]).is_file()
                     and file_sha256(out / prev["file"]) == prev["file_sha256"])
        plans.append((src, model, sha, options, prev, fresh))
    todo = [k for k, plan in enumerate(plans) if plan[5]]
    items: dict[int, dict] = {}
    for k, (src, model, sha, options, prev, fresh) in enumerate(plans):
        if not fresh:
            items[k] = dict(prev, source=str(src.path))
            reused.append(model.name)
    # each model is written as soon as it is built, and the index of those done every INDEX_EVERY
    # seconds: a stopped build of a large catalogue resumes where it stopped
    written = time.monotonic()
    # closed at once where a write fails, which ends its workers
    made = _stored if cluster is None else cluster.stored
    with contextlib.closing(made(models, todo, quiet=quiet, tips=tips)) as stored:
        for done, (k, blob, rows) in enumerate(stored, 1):
            src, model, sha, options, _, _ = plans[k]
            name = f"{_safe(model.name)}-{sha[:16]}.npz"
            with atomic_write(out / name, "wb") as handle:
                handle.write(blob)
            items[k] = {
                "name": model.name, "kind": model.kind, "units": model.units, "options": options, "file": name,
                "source": str(src.path), "source_sha256": sha, "file_sha256": hashlib.sha256(blob).hexdigest(),
                "table_rows": rows, "table_version": TABLE_VERSION, "store_version": STORE_VERSION,
                "builtin": src.builtin,
            }
            built.append(k)
            if done < len(todo) and time.monotonic() - written > INDEX_EVERY:
                _write_index(out, [items[j] for j in sorted(items)], complete=False)
                written = time.monotonic()
    items = [items[k] for k in range(len(plans))]
    _write_index(out, items, complete=True)
    keep = {item["file"] for item in items}
    removed = []
    for f in out.glob("*.npz"):
        if f.name not in keep:
            f.unlink()
            removed.append(f.name)
    return BuildReport(out, [plans[k][1].name for k in sorted(built)], reused, removed)


def open_models(*, db=None, models=None, warn=None, quiet: bool = True, units=None, scale=None,
                fields: bool = True) -> Database:
    """A database from ``db`` (a folder; ``fields``: :func:`load_database`'s) or built from ``models``."""
    if db is not None:
        return load_database(db, warn=warn, fields=fields)
    return build_entries(models, quiet=quiet, units=units, scale=scale)


def cache_folder() -> Path:
    """Where tactrec keeps databases it builds for itself (the demo's):
    ``$TACTREC_CACHE``, else ``$XDG_CACHE_HOME/tactrec``, else ``~/.cache/tactrec``."""
    if os.environ.get("TACTREC_CACHE"):
        return Path(os.environ["TACTREC_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "tactrec"


def cached_database(models: Iterable, *, name: str, quiet: bool = True) -> Database:
    """``models`` as a database in the cache folder ``name``: built the first
    time, then reused while the sources are unchanged.  Falls back to building
    in memory where the cache cannot be written."""
    models = list(models)
    folder = cache_folder() / name
    try:
        build_database(models, folder, quiet=quiet)
    except OSError:
        return build_entries(models, quiet=quiet)
    return load_database(folder)
