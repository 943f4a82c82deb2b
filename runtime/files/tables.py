"""The tables file: one versioned ``.npz`` with a JSON manifest inside.

Offline fitters write tables, the runtime reads them. The runtime owns the
format, so a puppetry machine needs nothing but the runtime to load them.

A tables file is untrusted input. It is opened with ``allow_pickle=False``
and every array is checked against the manifest (dtype, shape) and against
the schema of its kind (which sections must exist, which dimensions must
agree) before anything uses it. Every refusal raises :class:`TablesError`
naming the file and the field.

The contract, for each kind of table (the actor, the character, ...):

* the kind declares a :class:`TableSchema` (kind name, schema version, one
  :class:`Section` per array with its dtype and named dimensions, the
  channel groups of the manifest) and registers it (:func:`register_schema`);
* its class builds through :func:`coerce` (arrays to the section dtypes, for
  classes that accept any numeric input) and :func:`validate` (the checks a
  file gets, on arrays in memory), so a table is valid once built;
* it writes with :func:`save_tables` and reads with :func:`load_tables`,
  building itself inside :func:`naming_file` so its own refusals name the file.

Layout of the archive::

    __manifest__      uint8 array, UTF-8 JSON (see below)
    <section name>    one plain numeric array per section

Manifest fields::

    format            "facepuppet-tables"
    schema_version    int, the version of the kind's TableSchema when written
    kind              "character", "actor", ... (a registered TableSchema)
    created_by        "facepuppet <version>"
    units             "cm", "mm", "m" or "" for unitless tables
    sections          {name: {"shape": [...], "dtype": "float32", "kind": "..."}}
    dims              {named dimension: int}, e.g. {"n_vertices": 1234}
    channels          {group: [names...]}, e.g. {"shapes": ["jawOpen", ...]}
    settings          training settings (JSON object)
    input_hash        "sha256:<hex>" of the training inputs
    metrics           fit metrics (JSON object)
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from facepuppet.runtime.files.json_limits import JsonTextError, loads_limited
from facepuppet.runtime.files.outputs import atomic_path
from facepuppet.runtime.files.table_members import read_member
from facepuppet.runtime.files.tables_error import NO_FILE, TablesError

from facepuppet import __version__

FORMAT_NAME = "facepuppet-tables"
SCHEMA_VERSION = 1  # the schema version of a kind that declares none
MANIFEST_KEY = "__manifest__"
ALLOWED_UNITS = ("", "mm", "cm", "m")
ALLOWED_DTYPES = ("float32", "float64", "int32", "int64", "uint8", "uint16", "uint32", "bool")


@dataclass(frozen=True)
class Section:
    """What the schema of a kind requires of one array.

    ``shape`` lists dimensions as ints (fixed) or strings (named dimensions
    that must agree across the sections of one file, e.g. ``"n_vertices"``).
    A string of the form ``"n_shapes+1"`` is the named dimension plus one.
    ``max_bytes`` bounds the array below :data:`MAX_SECTION_BYTES` where the
    kind knows a tighter one (a section of file bytes kept whole); 0: no
    bound of its own.
    """

    dtype: str
    shape: tuple[int | str, ...]
    kind: str = ""
    optional: bool = False
    max_bytes: int = 0

    def __post_init__(self) -> None:
        if self.dtype not in ALLOWED_DTYPES:
            raise ValueError(f"Section dtype: expected one of {ALLOWED_DTYPES}, got {self.dtype!r}")
        for dim in self.shape:
            if not (isinstance(dim, int) or (isinstance(dim, str) and _dim_pattern(dim))):
                raise ValueError(f"Section shape: expected ints and names like 'n_shapes' or 'n_shapes+1', got {dim!r}")


def _dim_pattern(dim: str) -> bool:
    name, _, plus = dim.partition("+")
    return name.isidentifier() and (not plus or plus.isdigit())


@dataclass(frozen=True)
class TableSchema:
    """What one kind of tables file holds.

    Attributes
    ----------
    kind : str, the manifest's ``kind``
    sections : {name: Section}, the arrays, required unless ``optional``
    channels : tuple of str, the channel groups the manifest must list (``channels.<group>``)
    channel_dims : {group: named dimension}, a group's length must equal that dimension
    version : int, the schema version written, and the newest read; a kind that changes
        its sections raises it, so an older facepuppet refuses the new files with advice
    """

    kind: str
    sections: Mapping[str, Section]
    channels: tuple[str, ...] = ()
    channel_dims: Mapping[str, str] = field(default_factory=dict)
    version: int = SCHEMA_VERSION

    def __post_init__(self) -> None:
        if not (isinstance(self.version, int) and self.version >= 1):
            raise ValueError(f"TableSchema {self.kind!r} version: expected an int >= 1, got {self.version!r}")
        named = {str(d).partition("+")[0] for spec in self.sections.values() for d in spec.shape}
        for group, dim in self.channel_dims.items():
            if dim not in named:
                raise ValueError(f"TableSchema {self.kind!r} channel_dims[{group!r}]: {dim!r} is no section's "
                                 f"dimension")


_SCHEMAS: dict[str, TableSchema] = {}


def register_schema(schema: TableSchema) -> TableSchema:
    """Make a kind of tables known to :func:`load_tables` and :func:`save_tables`; returns the schema."""
    _SCHEMAS[schema.kind] = schema
    return schema


def registered_kinds() -> tuple[str, ...]:
    return tuple(sorted(_SCHEMAS))


def schema_of(kind: str, path: str | os.PathLike | None = None, field_name: str = "kind") -> TableSchema:
    """The registered schema of ``kind``; TablesError naming ``path`` and ``field_name`` if there is none."""
    schema = _SCHEMAS.get(kind) if isinstance(kind, str) else None
    if schema is None:
        raise TablesError(path, field_name, f"unknown kind {kind!r}; known: {', '.join(registered_kinds())}")
    return schema


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

    @property
    def metadata(self) -> dict[str, Any]:
        """Fresh copies of settings and metrics, and the input hash: a table class's ``metadata``."""
        return {"settings": dict(self.settings), "metrics": dict(self.metrics),
                "input_hash": self.manifest.get("input_hash", "")}

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


def coerce(schema: TableSchema, arrays: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The given arrays as C-contiguous, read-only arrays of their sections' dtypes.

    For table classes that take any numeric input (float64 from a fitter, lists
    from a test): ``{name: array-like}`` -> ``{name: ndarray}``, one entry per
    given name, no copy where an array already fits. Shapes are not checked
    here; :func:`validate` does that.
    """
    out: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        spec = schema.sections.get(name)
        if spec is None:
            raise TablesError(None, name, f"not a section of kind {schema.kind!r}")
        arr = np.ascontiguousarray(value, dtype=spec.dtype)
        arr.setflags(write=False)
        out[name] = arr
    return out


def validate(
    schema: TableSchema,
    arrays: Mapping[str, np.ndarray],
    channels: Mapping[str, Any],
    path: str | os.PathLike | None = None,
) -> dict[str, int]:
    """Check arrays and channel lists against a kind's schema; return the named dimensions.

    The checks a tables file gets when saved and loaded, for tables in memory:
    every required section is there and no unknown one; each has its section's
    dtype and shape, the named dimensions agree across sections (and with the
    channel lists of ``channel_dims``); float arrays are finite; every channel
    group of the schema is listed, as non-empty, distinct strings.

    Parameters
    ----------
    schema : TableSchema
    arrays : {section name: ndarray}
    channels : {group: list of str}
    path : the file the arrays come from or go to, named in errors (None: in memory)

    Returns
    -------
    dims : {named dimension: int}, e.g. {"n_vertices": 1234, "n_shapes": 52}
    """
    extra = sorted(set(arrays) - set(schema.sections))
    if extra:
        raise TablesError(path, extra[0], f"not a section of kind {schema.kind!r}")
    dims = _section_dims(schema, arrays, path)
    for name, arr in arrays.items():
        bound = schema.sections[name].max_bytes
        if bound and arr.nbytes > bound:
            raise TablesError(path, name, f"{arr.nbytes} bytes, more than the limit of {bound} bytes")
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise TablesError(path, name, "contains NaN or infinity")
    _check_channels(schema, channels, dims, path)
    return dims


@contextmanager
def naming_file(path: str | os.PathLike) -> Iterator[None]:
    """Inside it, a TablesError about tables in memory (a class's own checks) names ``path`` instead.

    A table class's ``load`` builds the class inside it, so that the refusals
    of the class's constructor name the file that was loaded.
    """
    try:
        yield
    except TablesError as exc:
        if exc.path != NO_FILE:
            raise
        raise TablesError(path, exc.field, exc.problem) from None


def _section_dims(schema: TableSchema, arrays: Mapping[str, np.ndarray], path) -> dict[str, int]:
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
    metadata: Mapping[str, Any] | None = None,
    compress: bool = True,
) -> Path:
    """Validate (:func:`validate`) and write a tables file atomically; return its path.

    Parameters
    ----------
    path : where to write the ``.npz``
    kind : a registered kind (``"character"``, ...)
    arrays : {section name: ndarray} of the kind's sections
    units : one of ALLOWED_UNITS
    channels : {group: list of str}, the kind's channel groups
    settings, input_hash, metrics : the manifest fields of the same names
    metadata : a table class's ``metadata`` ({"settings", "metrics", "input_hash"}, any of them),
        taken for those of ``settings``, ``input_hash`` and ``metrics`` not given
    compress : zip-deflate the arrays

    The file appears under its name only once it is complete (written to a
    temporary file beside it, then renamed), so a crash never leaves half a
    tables file behind.
    """

    path = Path(path)
    schema = schema_of(kind, path)
    if units not in ALLOWED_UNITS:
        raise TablesError(path, "units", f"must be one of {ALLOWED_UNITS}, got {units!r}")
    metadata = metadata or {}
    settings = metadata.get("settings", {}) if settings is None else settings
    metrics = metadata.get("metrics", {}) if metrics is None else metrics
    input_hash = input_hash or metadata.get("input_hash", "")
    clean: dict[str, np.ndarray] = {}
    for name, arr in arrays.items():
        if name == MANIFEST_KEY or not name.isidentifier():
            raise TablesError(path, name, "section names must be identifiers")
        arr = np.ascontiguousarray(arr)
        if arr.dtype.name not in ALLOWED_DTYPES:
            raise TablesError(path, name, f"dtype {arr.dtype.name} cannot be stored; use one of {ALLOWED_DTYPES}")
        clean[name] = arr
    channels = {k: list(v) for k, v in (channels or {}).items()}
    dims = validate(schema, clean, channels, path)
    manifest = {
        "format": FORMAT_NAME,
        "schema_version": schema.version,
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
    # atomic, with the permissions a plain open() would give (a bare mkstemp file is 0600)
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        (np.savez_compressed if compress else np.savez)(handle, **payload)
        handle.flush()
        os.fsync(handle.fileno())
    return path


MAX_MANIFEST_BYTES = 4 << 20  # a manifest is a few kB; 4 MiB is far beyond any real one
MAX_MANIFEST_DEPTH = 32  # nesting of JSON objects and lists in a manifest
MAX_SECTION_BYTES = 1 << 30  # one section's array; the largest real table (ICT deltas) is ~7 MB
def _parse_manifest(archive: zipfile.ZipFile, member: str, path) -> dict:
    """The manifest member, size- and depth-checked before it is parsed."""
    raw = read_member(archive, member, path, "manifest", limit=MAX_MANIFEST_BYTES)
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise TablesError(path, "manifest", f"must be a uint8 byte string, found {raw.dtype} {raw.shape}")
    try:
        manifest = loads_limited(raw.tobytes(), "manifest", max_bytes=MAX_MANIFEST_BYTES,
                                 max_depth=MAX_MANIFEST_DEPTH)
    except JsonTextError as exc:
        raise TablesError(path, "manifest", exc.problem) from None
    if not isinstance(manifest, dict):
        raise TablesError(path, "manifest", "must be a JSON object")
    return manifest


def _short(value: Any) -> str:
    """A manifest value for a message: its repr, cut short (a 5000-digit int has no str())."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of {value.bit_length()} bits"
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


_MANIFEST_TYPES = {  # field: (types, what a message calls them)
    "format": (str, "a string"),
    "kind": (str, "a string"),
    "created_by": (str, "a string"),
    "units": (str, "a string"),
    "input_hash": (str, "a string"),
    "sections": (dict, "an object"),
    "dims": (dict, "an object"),
    "channels": (dict, "an object"),
    "settings": (dict, "an object"),
    "metrics": (dict, "an object"),
}


def _check_manifest_fields(manifest: Mapping[str, Any], path) -> None:
    """Each known top-level field of the manifest, where present, has its JSON type."""
    if manifest.get("format") != FORMAT_NAME:
        raise TablesError(path, "manifest.format", f"must be {FORMAT_NAME!r}, found {_short(manifest.get('format'))}")
    version = manifest.get("schema_version")
    if not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise TablesError(path, "manifest.schema_version", f"must be a positive integer, found {_short(version)}")
    for name, (types, what) in _MANIFEST_TYPES.items():
        if name in manifest and not isinstance(manifest[name], types):
            raise TablesError(path, f"manifest.{name}", f"must be {what}, found {type(manifest[name]).__name__} "
                                                       f"{_short(manifest[name])}")
    for name, meta in manifest.get("sections", {}).items():
        if not (isinstance(meta, dict) and isinstance(meta.get("shape"), list)
                and all(isinstance(d, int) and not isinstance(d, bool) and 0 <= d < 1 << 62 for d in meta["shape"])
                and meta.get("dtype") in ALLOWED_DTYPES):
            raise TablesError(path, f"manifest.sections.{name}",
                              f"must be {{\"shape\": [ints >= 0], \"dtype\": one of {ALLOWED_DTYPES}}}, "
                              f"found {_short(meta)}")


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
        pickled file, a schema version newer than the kind's, another kind,
        arrays whose dtype or shape disagree with the manifest, or arrays and
        channels that :func:`validate` refuses.
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
        manifest = _parse_manifest(archive, members[MANIFEST_KEY], path)
        _check_manifest_fields(manifest, path)
        version = manifest["schema_version"]
        file_kind = manifest.get("kind")
        if kind is not None and file_kind != kind:
            raise TablesError(path, "manifest.kind", f"expected {kind!r} tables, found {_short(file_kind)}")
        schema = schema_of(file_kind, path, "manifest.kind")
        if version > schema.version:
            raise TablesError(
                path, "manifest.schema_version",
                f"is {_short(version)}, written by a newer facepuppet ({manifest.get('created_by', '?')}); "
                f"this one reads {file_kind} schema versions up to {schema.version}. Upgrade facepuppet to load it.",
            )
        sections = manifest.get("sections")
        if not isinstance(sections, dict):
            raise TablesError(path, "manifest.sections", "must be an object")
        for name in members:
            if name != MANIFEST_KEY and name not in sections:
                raise TablesError(path, name, "is in the archive but not listed in the manifest")
        for name in sections:
            if name not in members:
                raise TablesError(path, name, "listed in the manifest but missing from the archive")
            if name not in schema.sections:
                raise TablesError(path, name, f"not a section of kind {file_kind!r}")
        # The declared shapes must fit the schema before any data is read: zero-byte views stand in.
        _section_dims(schema, {name: _placeholder(meta) for name, meta in sections.items()}, path)
        arrays: dict[str, np.ndarray] = {}
        for name, meta in sections.items():
            bound = schema.sections[name].max_bytes
            arr = read_member(archive, members[name], path, name, expect=(meta["shape"], meta["dtype"]),
                              limit=min(bound, MAX_SECTION_BYTES) if bound else MAX_SECTION_BYTES)
            arr.setflags(write=False)
            arrays[name] = arr
    channels = manifest.get("channels", {})
    if not isinstance(channels, dict):
        raise TablesError(path, "manifest.channels", "must be an object")
    validate(schema, arrays, channels, path)
    units = manifest.get("units", "")
    if units not in ALLOWED_UNITS:
        raise TablesError(path, "manifest.units", f"must be one of {ALLOWED_UNITS}, found {units!r}")
    return Tables(kind=file_kind, arrays=arrays, manifest=manifest, path=str(path))


def _placeholder(meta: Mapping[str, Any]) -> np.ndarray:
    """A zero-byte array with the declared shape and dtype of a section (for checks before reading)."""
    return np.lib.stride_tricks.as_strided(np.zeros(1, dtype=meta["dtype"]), shape=tuple(meta["shape"]),
                                           strides=(0,) * len(meta["shape"]), writeable=False)
