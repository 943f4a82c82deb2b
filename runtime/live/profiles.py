"""Profiles: the whole live config (neutral included) saved, loaded and written as TOML.

A profile is a ``--config`` file (the schema of :mod:`~facepuppet.runtime.live.config`) with every setting
written out, the calibrated neutral in ``[neutral]`` and what it was made for in ``[profile]``::

    [profile]
    character = "ict.npz"       # the character file's name
    input = "livelinkface"      # the input kind
    saved = "2026-12-02T00:30:00+00:00"

``--profile NAME`` names ``$XDG_CONFIG_HOME/facepuppet/profiles/NAME.toml`` (``~/.config`` without
XDG_CONFIG_HOME); anything with a ``/`` or ending in ``.toml`` is a path. A profile that does not exist yet
starts from the defaults and is created by its first :meth:`Profile.save`. Loading one made for another
character or input logs a warning (the settings still apply: names are matched by spelling).

Files are written atomically (:func:`facepuppet.runtime.files.outputs.atomic_path`): a crash mid-save leaves the old
profile. :func:`config_to_toml` is also what a recording keeps of the config in force.
"""

from __future__ import annotations

import datetime
import json
import logging
import math
import os
import re
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.files.outputs import atomic_path
from facepuppet.runtime.live.config import (
    REGIONS,
    ChannelSettings,
    LiveConfig,
    load_live_config,
    parse_live_config,
    read_toml,
    read_toml_file,
)
from facepuppet.runtime.live.mix import MixSettings

logger = logging.getLogger(__name__)

_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]*")
_BARE = re.compile(r"[A-Za-z0-9_-]+")


def profiles_dir() -> Path:
    """``$XDG_CONFIG_HOME/facepuppet/profiles`` (``~/.config/facepuppet/profiles`` without XDG_CONFIG_HOME)."""
    base = os.environ.get("XDG_CONFIG_HOME") or ""
    root = Path(base) if base and Path(base).is_absolute() else Path.home() / ".config"
    return root / "facepuppet" / "profiles"


def profile_path(spec: str | os.PathLike) -> Path:
    """The file of ``--profile SPEC``: a path (has a ``/`` or ends in ``.toml``) or a name under :func:`profiles_dir`.

    Raises
    ------
    ValueError
        naming ``--profile`` for an empty name or one with characters a file name should not have.
    """
    text = os.fspath(spec)
    if "/" in text or os.sep in text or text.endswith(".toml"):
        return Path(text).expanduser()
    if not _NAME.fullmatch(text):
        raise UsageError(f"--profile {text!r}: a profile name is letters, digits, '_', '-' and '.' (not first); "
                         "or give a path to a .toml file")
    return profiles_dir() / f"{text}.toml"


# -- TOML out ---------------------------------------------------------------------------------------------


def _key(k: str) -> str:
    return k if _BARE.fullmatch(k) else _string(k)


def _string(s: str) -> str:
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"config value {v!r}: TOML profiles hold finite numbers only")
        return repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"config value {v!r} ({type(v).__name__}) has no TOML form here")


def dumps_toml(doc: dict) -> str:
    """TOML text of nested dicts of bools, ints, finite floats, strings and arrays (tables: ``[a.b]``)."""
    lines: list[str] = []

    def walk(table: dict, prefix: tuple[str, ...]) -> None:
        scalars = [(k, v) for k, v in table.items() if not isinstance(v, dict)]
        tables = [(k, v) for k, v in table.items() if isinstance(v, dict)]
        if prefix and (scalars or not tables):
            lines.append(f"[{'.'.join(_key(p) for p in prefix)}]")
        for k, v in scalars:
            lines.append(f"{_key(k)} = {_value(v)}")
        if scalars and prefix:
            lines.append("")
        for k, v in tables:
            walk(v, (*prefix, k))

    walk(doc, ())
    return "\n".join(lines).rstrip() + "\n"


def _channel_dict(c: ChannelSettings) -> dict:
    out = {"gain": c.gain, "clamp": list(c.clamp), "curve": c.curve, "threshold": c.threshold}
    if c.input_range is not None:
        out["input_range"] = list(c.input_range)
    if c.output_range is not None:
        out["output_range"] = list(c.output_range)
    return out


def config_to_dict(config: LiveConfig) -> dict:
    """The TOML document of ``config``: every setting written out (what :func:`parse_live_config` reads back)."""
    doc: dict = {
        "filter": {r: {"min_cutoff": f.min_cutoff, "beta": f.beta, "d_cutoff": f.d_cutoff}
                   for r, f in config.filters.items() if r in REGIONS},
        "tracking_loss": {"timeout_s": config.timeout_s, "ease_out_s": config.ease_out_s,
                          "ease_in_s": config.ease_in_s, **config.loss.to_toml()},
        "calibration": {"capture_s": config.capture_s},
        "face": {"link_blinks": config.link_blinks, "mirror": config.mirror},
        "default_channel": _channel_dict(config.default_channel),
    }
    if config.channels:
        doc["channels"] = {k: _channel_dict(c) for k, c in config.channels.items()}
    if config.neutral is not None:
        n = config.neutral
        doc["neutral"] = {"channels": list(n.channels), "weights": list(n.weights), "rotation": list(n.rotation)}
        if n.translation is not None:
            doc["neutral"]["translation"] = list(n.translation)
    m = config.mapping
    if not m.empty:
        doc["mapping"] = {"emotions": m.emotions}
        if m.channels:
            doc["mapping"]["channels"] = {
                m.written.get(k, k): [{"to": t.to, "weight": t.weight} for t in targets] if targets else False
                for k, targets in m.channels.items()}
    mix = config.mix
    if not mix.empty or mix.ease_s != MixSettings().ease_s:
        doc["mix"] = {**({"order": list(mix.order)} if mix.order is not None else {}), "ease_s": mix.ease_s}
        if mix.regions:
            doc["mix"]["regions"] = {r: list(v) for r, v in mix.regions.items()}
        if mix.channels:
            doc["mix"]["channels"] = {k: list(v) for k, v in mix.channels.items()}
    if config.hotkeys:
        doc["hotkeys"] = {key: dict(command) for key, command in config.hotkeys}
    return doc


def config_to_toml(config: LiveConfig, made_for: dict | None = None) -> str:
    """TOML text of ``config`` (``made_for``: the ``[profile]`` table, first)."""
    doc = {"profile": dict(made_for)} if made_for else {}
    doc.update(config_to_dict(config))
    return dumps_toml(doc)


def parse_config_text(text: str, where: str, known_channels: Iterable[str] | None = None) -> LiveConfig:
    """LiveConfig from TOML text (a recording's config, say), checked as a ``--config`` file is
    (:func:`~facepuppet.runtime.live.config.read_toml`); LiveConfigError naming ``where``."""
    return parse_live_config(read_toml(text, where), where, known_channels)


# -- profiles -----------------------------------------------------------------------------------------


def read_made_for(path: str | os.PathLike) -> dict:
    """The ``[profile]`` table of a profile file ({} when it has none); LiveConfigError naming the file when
    it cannot be read as a config."""
    _, data = read_toml_file(path, "profile file")
    made = data.get("profile", {})
    return dict(made) if isinstance(made, dict) else {}


class Profile:
    """One profile file and what the run using it is (for the ``[profile]`` table and the mismatch warning).

    Parameters
    ----------
    path : Path, the file (see :func:`profile_path`)
    character : str, the character file's name this run draws
    input_kind : str, this run's input kind
    known_channels : names a ``[channels.NAME]`` may use besides ARKit's (as :func:`parse_live_config`)
    log : callable taking one str

    Attributes
    ----------
    path : Path, the file Save writes (Save as changes it)
    saved : LiveConfig, the config as last loaded or saved (what Revert gives back); defaults for a new profile
    exists : bool, whether the file was there when loaded (or has been saved since)
    """

    def __init__(self, path: str | os.PathLike, character: str = "", input_kind: str = "",
                 known_channels: Iterable[str] = (), log: Callable[[str], None] = logger.info) -> None:
        self.path = Path(path)
        self.character = character
        self.input_kind = input_kind
        self.known = tuple(known_channels)
        self.log = log
        self.exists = False
        self.saved = LiveConfig(path=str(self.path))

    def load(self) -> LiveConfig:
        """Read the file (defaults when it does not exist yet); warns when it was made for another character or
        input. LiveConfigError naming the file and key for a bad one."""
        if not self.path.exists():
            self.exists = False
            self.log(f"profile: {self.path} does not exist yet; starting from the defaults (Save creates it)")
            self.saved = LiveConfig(path=str(self.path))
            return self.saved
        config = load_live_config(self.path, self.known)
        self.exists = True
        self.saved = config
        made = read_made_for(self.path)
        self.log(f"profile: {self.path}" + (f" (made for {made.get('character', '?')}, "
                                            f"input {made.get('input', '?')})" if made else ""))
        for what, mine in (("character", self.character), ("input", self.input_kind)):
            theirs = made.get(what)
            if mine and theirs and theirs != mine:
                self.log(f"profile: warning: {self.path} was made for {what} {theirs!r}, this run's {what} is "
                         f"{mine!r}; its settings apply by channel name and may not fit")
        return config

    def save(self, config: LiveConfig) -> Path:
        """Write ``config`` (neutral included) to :attr:`path`, atomically; returns the path."""

        made = {"character": self.character, "input": self.input_kind,
                "saved": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")}
        text = config_to_toml(config, {k: v for k, v in made.items() if v})
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.path) as temp:
            temp.write_text(text, encoding="utf-8")
        self.exists = True
        self.saved = replace(config, path=str(self.path))
        self.log(f"profile: saved {self.path}")
        return self.path

    def save_as(self, path: str | os.PathLike, config: LiveConfig) -> Path:
        """Save to another file (a name or a path, as ``--profile``), which becomes this profile's file."""
        self.path = profile_path(path)
        return self.save(config)

    def revert(self) -> LiveConfig:
        """The config as last loaded or saved (read again from the file when it is there)."""
        return self.load() if self.path.exists() else self.saved
