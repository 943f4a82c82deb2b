"""The tables file: one versioned ``.npz`` with a JSON manifest inside.

Offline fitters write tables, the runtime reads them. The runtime owns the
format, so a puppetry machine needs nothing but the runtime to load them.

A tables file is untrusted input. It is opened with ``allow_pickle=False``
and every array is checked against the manifest (dtype, shape) and against
the schema of its kind (which sections must exist, which dimensions must
agree) before anything uses it. Every refusal raises :class:`TablesError`
naming the file and the field.

Layout of the archive::

    __manifest__      uint8 array, UTF-8 JSON (see below)
    <section name>    one plain numeric array per section

Manifest fields::

    format            "facepuppet-tables"
    schema_version    int, SCHEMA_VERSION when written
    kind              "character", "actor", ... (a registered TableSchema)
    created_by        "facepuppet <version>"
    units             "cm", "mm", "m" or "" for unitless tables
    sections          {name: {"shape": [...], "dtype": "float32", "kind": "..."}}
    channels          {group: [names...]}, e.g. {"shapes": ["jawOpen", ...]}
    settings          training settings (JSON object)
    input_hash        "sha256:<hex>" of the training inputs
    metrics           fit metrics (JSON object)
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

FORMAT_NAME = "facepuppet-tables"
SCHEMA_VERSION = 1
MANIFEST_KEY = "__manifest__"
ALLOWED_UNITS = ("", "mm", "cm", "m")
ALLOWED_DTYPES = ("float32", "float64", "int32", "int64", "uint8", "uint16", "uint32", "bool")


class TablesError(ValueError):
    """A tables file (or tables about to be written) is not acceptable.

    The message names the file and the field, what was expected and what was
    found.
    """

    def __init__(self, path: str | os.PathLike | None, field_name: str, problem: str):
        self.path = str(path) if path is not None else "<tables>"
        self.field = field_name
        self.problem = problem
        super().__init__(f"{self.path}: {field_name}: {problem}")


@dataclass(frozen=True)
class Section:
    """What the schema of a kind requires of one array.

    ``shape`` lists dimensions as ints (fixed) or strings (named dimensions
    that must agree across the sections of one file, e.g. ``"n_vertices"``).
    A string of the form ``"n_shapes+1"`` is the named dimension plus one.
    """

    dtype: str
    shape: tuple[int | str, ...]
    kind: str = ""
    optional: bool = False


@dataclass(frozen=True)
class TableSchema:
    """The sections and channel groups a kind of tables must carry."""

    kind: str
    sections: Mapping[str, Section]
    channels: tuple[str, ...] = ()
    # channel group -> named dimension its length must equal
    channel_dims: Mapping[str, str] = field(default_factory=dict)


_SCHEMAS: dict[str, TableSchema] = {}


def register_schema(schema: TableSchema) -> TableSchema:
    """Make a kind of tables known to :func:`load_tables` and :func:`save_tables`."""
    _SCHEMAS[schema.kind] = schema
    return schema


def registered_kinds() -> tuple[str, ...]:
    return tuple(sorted(_SCHEMAS))


@dataclass(frozen=True)
class Tables:
    """A loaded, validated tables file."""

    kind: str
    arrays: Mapping[str, np.ndarray]
    manifest: Mapping[str, Any]
    path: str | None = None

    @property
    def channels(self) -> Mapping[str, list[str]]:
        return self.manifest.get("channels", {})

    @property
    def units(self) -> str:
        return self.manifest.get("units", "")

    @property
    def metrics(self) -> Mapping[str, Any]:
        return self.manifest.get("metrics", {})

    @property
    def settings(self) -> Mapping[str, Any]:
        return self.manifest.get("settings", {})

    def __getitem__(self, name: str) -> np.ndarray:
        return self.arrays[name]


def hash_inputs(*parts: bytes | str | os.PathLike | np.ndarray) -> str:
    """``sha256:<hex>`` over the given byte strings, arrays and files, in order."""
    digest = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            digest.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, (bytes, bytearray)):
            digest.update(part)
        elif isinstance(part, str) and not os.path.exists(part):
            digest.update(part.encode("utf-8"))
        else:
            with open(part, "rb") as handle:
                for block in iter(lambda: handle.read(1 << 20), b""):
                    digest.update(block)
    return "sha256:" + digest.hexdigest()


def _json_clean(value: Any, where: str, path) -> Any:
    """Check that a manifest value is plain JSON with finite numbers."""
    if isinstance(value, dict):
        return {str(k): _json_clean(v, f"{where}.{k}", path) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_clean(v, f"{where}[{i}]", path) for i, v in enumerate(value)]
    if isinstance(value, (np.floating, float)):
        if not math.isfinite(float(value)):
            raise TablesError(path, where, f"must be a finite number, got {value!r}")
        return float(value)
    if isinstance(value, (np.integer, int, bool)) or value is None or isinstance(value, str):
        return value.item() if isinstance(value, np.generic) else value
    raise TablesError(path, where, f"must be JSON (dict, list, str, number), got {type(value).__name__}")


def _resolve_dims(schema: TableSchema, arrays: Mapping[str, np.ndarray], path) -> dict[str, int]:
    """Check each array against its section spec and return the named dimensions."""
    dims: dict[str, tuple[int, str]] = {}
    for name, spec in schema.sections.items():
        if name not in arrays:
            if spec.optional:
                continue
            raise TablesError(path, name, f"missing section (kind {schema.kind!r} requires it)")
        arr = arrays[name]
        if arr.dtype.name != spec.dtype:
            raise TablesError(path, name, f"dtype must be {spec.dtype}, found {arr.dtype.name}")
        if arr.ndim != len(spec.shape):
            raise TablesError(
                path, name, f"must have shape {_fmt_shape(spec.shape)}, found {tuple(arr.shape)}"
            )
        for axis, (want, got) in enumerate(zip(spec.shape, arr.shape)):
            if isinstance(want, int):
                if got != want:
                    raise TablesError(
                        path, name,
                        f"axis {axis} must be {want} (shape {_fmt_shape(spec.shape)}), found {tuple(arr.shape)}",
                    )
                continue
            dim, plus = (want.split("+") + ["0"])[:2]
            value = got - int(plus)
            if dim in dims and dims[dim][0] != value:
                first_value, first_section = dims[dim]
                raise TablesError(
                    path, name,
                    f"axis {axis} is {want} = {got}, but section {first_section!r} says "
                    f"{dim} = {first_value}",
                )
            dims.setdefault(dim, (value, name))
    return {k: v for k, (v, _) in dims.items()}


def _fmt_shape(shape) -> str:
    return "(" + ", ".join(str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def _check_channels(schema: TableSchema, channels: Mapping[str, Any], dims: Mapping[str, int], path):
    for group in schema.channels:
        if group not in channels:
            raise TablesError(path, f"channels.{group}", "missing channel name list")
    for group, names in channels.items():
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise TablesError(path, f"channels.{group}", "must be a list of non-empty strings")
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise TablesError(path, f"channels.{group}", f"duplicate names {dup[:5]}")
        dim = schema.channel_dims.get(group)
        if dim is not None and dim in dims and dims[dim] != len(names):
            raise TablesError(
                path, f"channels.{group}", f"has {len(names)} names but {dim} = {dims[dim]}"
            )


def save_tables(
    path: str | os.PathLike,
    kind: str,
    arrays: Mapping[str, np.ndarray],
    *,
    units: str = "",
    channels: Mapping[str, list[str]] | None = None,
    settings: Mapping[str, Any] | None = None,
    input_hash: str = "",
    metrics: Mapping[str, Any] | None = None,
    compress: bool = True,
) -> Path:
    """Validate and write a tables file atomically; return its path.

    The file appears under its name only once it is complete (written to a
    temporary file beside it, then renamed), so a crash never leaves half a
    tables file behind.
    """
    from facepuppet import __version__

    path = Path(path)
    schema = _SCHEMAS.get(kind)
    if schema is None:
        raise TablesError(path, "kind", f"unknown kind {kind!r}; known: {', '.join(registered_kinds())}")
    if units not in ALLOWED_UNITS:
        raise TablesError(path, "units", f"must be one of {ALLOWED_UNITS}, got {units!r}")
    clean: dict[str, np.ndarray] = {}
    for name, arr in arrays.items():
        if name == MANIFEST_KEY or not name.isidentifier():
            raise TablesError(path, name, "section names must be identifiers")
        arr = np.ascontiguousarray(arr)
        if arr.dtype.name not in ALLOWED_DTYPES:
            raise TablesError(path, name, f"dtype {arr.dtype.name} cannot be stored; use one of {ALLOWED_DTYPES}")
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise TablesError(path, name, "contains NaN or infinity")
        clean[name] = arr
    extra = sorted(set(clean) - set(schema.sections))
    if extra:
        raise TablesError(path, extra[0], f"not a section of kind {kind!r}")
    dims = _resolve_dims(schema, clean, path)
    channels = {k: list(v) for k, v in (channels or {}).items()}
    _check_channels(schema, channels, dims, path)
    manifest = {
        "format": FORMAT_NAME,
        "schema_version": SCHEMA_VERSION,
        "kind": kind,
        "created_by": f"facepuppet {__version__}",
        "units": units,
        "sections": {
            name: {
                "shape": list(arr.shape),
                "dtype": arr.dtype.name,
                "kind": schema.sections[name].kind,
            }
            for name, arr in clean.items()
        },
        "dims": dims,
        "channels": channels,
        "settings": _json_clean(dict(settings or {}), "settings", path),
        "input_hash": input_hash,
        "metrics": _json_clean(dict(metrics or {}), "metrics", path),
    }
    blob = json.dumps(manifest, indent=1, sort_keys=True).encode("utf-8")
    payload = {MANIFEST_KEY: np.frombuffer(blob, dtype=np.uint8), **clean}
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            (np.savez_compressed if compress else np.savez)(handle, **payload)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _read_member(archive: zipfile.ZipFile, member: str, path, field_name: str) -> np.ndarray:
    try:
        raw = archive.read(member)
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise TablesError(path, field_name, f"cannot be read, the file is damaged ({exc})") from None
    except Exception as exc:  # zlib.error and friends on garbled data
        raise TablesError(path, field_name, f"cannot be read, the file is damaged ({exc})") from None
    try:
        return np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
    except ValueError as exc:
        if "pickle" in str(exc).lower() or "object" in str(exc).lower():
            raise TablesError(
                path, field_name, "holds pickled Python objects; tables files are never unpickled"
            ) from None
        raise TablesError(path, field_name, f"is not a valid array ({exc})") from None
    except Exception as exc:
        raise TablesError(path, field_name, f"is not a valid array ({exc})") from None


def load_tables(path: str | os.PathLike, kind: str | None = None) -> Tables:
    """Open and validate a tables file.

    Parameters
    ----------
    path : path of the ``.npz``
    kind : the kind the caller needs (``"character"``, ...), or None for any
        registered kind.

    Raises
    ------
    TablesError
        naming the file and field, for a missing, truncated, garbled or
        pickled file, a newer schema version, another kind, or arrays whose
        dtype or shape disagree with the manifest or the schema.
    """
    path = Path(path)
    if not path.is_file():
        raise TablesError(path, "file", "does not exist" if not path.exists() else "is not a file")
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, EOFError) as exc:
        raise TablesError(
            path, "file", f"is not a tables file (not a readable .npz archive: {exc}); truncated or garbled?"
        ) from None
    with archive:
        members = {name[:-4] if name.endswith(".npy") else name: name for name in archive.namelist()}
        if MANIFEST_KEY not in members:
            raise TablesError(path, "manifest", "missing (not a facepuppet tables file)")
        raw = _read_member(archive, members[MANIFEST_KEY], path, "manifest")
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise TablesError(path, "manifest", f"must be a uint8 byte string, found {raw.dtype} {raw.shape}")
        try:
            manifest = json.loads(raw.tobytes().decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise TablesError(path, "manifest", f"is not valid UTF-8 JSON ({exc})") from None
        if not isinstance(manifest, dict):
            raise TablesError(path, "manifest", "must be a JSON object")
        if manifest.get("format") != FORMAT_NAME:
            raise TablesError(path, "manifest.format", f"must be {FORMAT_NAME!r}, found {manifest.get('format')!r}")
        version = manifest.get("schema_version")
        if not isinstance(version, int) or isinstance(version, bool) or version < 1:
            raise TablesError(path, "manifest.schema_version", f"must be a positive integer, found {version!r}")
        if version > SCHEMA_VERSION:
            raise TablesError(
                path, "manifest.schema_version",
                f"is {version}, written by a newer facepuppet ({manifest.get('created_by', '?')}); "
                f"this one reads schema versions up to {SCHEMA_VERSION}. Upgrade facepuppet to load it.",
            )
        file_kind = manifest.get("kind")
        if kind is not None and file_kind != kind:
            raise TablesError(path, "manifest.kind", f"expected {kind!r} tables, found {file_kind!r}")
        schema = _SCHEMAS.get(file_kind)
        if schema is None:
            raise TablesError(path, "manifest.kind", f"unknown kind {file_kind!r}; known: {', '.join(registered_kinds())}")
        sections = manifest.get("sections")
        if not isinstance(sections, dict):
            raise TablesError(path, "manifest.sections", "must be an object")
        for name in members:
            if name != MANIFEST_KEY and name not in sections:
                raise TablesError(path, name, "is in the archive but not listed in the manifest")
        arrays: dict[str, np.ndarray] = {}
        for name, meta in sections.items():
            if name not in members:
                raise TablesError(path, name, "listed in the manifest but missing from the archive")
            if name not in schema.sections:
                raise TablesError(path, name, f"not a section of kind {file_kind!r}")
            arr = _read_member(archive, members[name], path, name)
            if not isinstance(meta, dict) or list(arr.shape) != meta.get("shape") or arr.dtype.name != meta.get("dtype"):
                raise TablesError(
                    path, name,
                    f"manifest says shape {meta.get('shape') if isinstance(meta, dict) else '?'} "
                    f"dtype {meta.get('dtype') if isinstance(meta, dict) else '?'}, "
                    f"archive holds shape {list(arr.shape)} dtype {arr.dtype.name}",
                )
            if arr.dtype.kind == "f" and not np.isfinite(arr).all():
                raise TablesError(path, name, "contains NaN or infinity")
            arr.setflags(write=False)
            arrays[name] = arr
    dims = _resolve_dims(schema, arrays, path)
    channels = manifest.get("channels", {})
    if not isinstance(channels, dict):
        raise TablesError(path, "manifest.channels", "must be an object")
    _check_channels(schema, channels, dims, path)
    units = manifest.get("units", "")
    if units not in ALLOWED_UNITS:
        raise TablesError(path, "manifest.units", f"must be one of {ALLOWED_UNITS}, found {units!r}")
    return Tables(kind=file_kind, arrays=arrays, manifest=manifest, path=str(path))
