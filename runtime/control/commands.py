"""The control verbs a show is steered by, one checked form for every way they arrive.

A command comes as a JSON object over the WebSocket (``{"verb": "expression", "name": "Joy", "action": "on"}``),
as an OSC message (``/facepuppet/expression/on Joy``) or from a hotkey (a ``[hotkeys]`` table of the config,
the same object as TOML). Each is checked here once, at the door, into a :class:`Command`; what is wrong is a
:class:`CommandError` naming the field, which the server answers and counts and never lets go further.

======================  ==============================================  ======================================
verb                    fields (JSON)                                   OSC address and arguments
======================  ==============================================  ======================================
``expression``          ``name``; ``action`` on / off / toggle / for;   ``/facepuppet/expression/ACTION``
                        ``value`` 0..1 (1); ``fade`` s (0.15);          ``s name [f fade]``; ``for``:
                        ``seconds`` (``for`` only)                      ``s name f seconds [f fade]``
``calibrate``           none                                            ``/facepuppet/calibrate``
``profile``             ``name`` (a profile name, never a path)         ``/facepuppet/profile s name``
``record``              ``action`` start / stop; ``name`` (start)       ``/facepuppet/record/ACTION [s name]``
``framing``             ``framing`` body / head / face; ``zoom`` > 0;   ``/facepuppet/framing s framing
                        ``pan`` [x, y] in view halves                   [f zoom f pan_x f pan_y]``
``list``                none: the expressions and profiles              (WebSocket only: a reply)
``status``              none: tracking, latency, recording, counters    (WebSocket only)
``subscribe``           ``rate`` Hz (0 stops): status and weights       (WebSocket only)
``view``                ``fps`` (0 stops): the drawn frames, RGBA       (WebSocket only)
======================  ==============================================  ======================================

Every object may carry an ``id`` (a string or number of the client's), echoed in the reply. With a token in
force, OSC messages carry it as their first argument (a WebSocket gives it once, in its URL).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from facepuppet.runtime.errors import FacepuppetError

EXPRESSION_ACTIONS = ("on", "off", "toggle", "for")
RECORD_ACTIONS = ("start", "stop")
FRAMINGS = ("body", "head", "face")
SHOW_VERBS = ("expression", "calibrate", "profile", "record", "framing")  # applied at the next tick
QUERY_VERBS = ("list", "status", "subscribe", "view")  # answered by the server itself
VERBS = SHOW_VERBS + QUERY_VERBS
DEFAULT_FADE_S = 0.15
MAX_FADE_S = 60.0
MAX_FOR_S = 3600.0
MAX_RATE_HZ = 60.0
MAX_NAME = 128
MAX_ZOOM = 20.0
MAX_PAN = 4.0
OSC_PREFIX = "/facepuppet/"
_PROFILE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")
_RECORD_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}")


class CommandError(FacepuppetError, ValueError):
    """A command that cannot be applied: the message names the field and what was expected."""


@dataclass(frozen=True)
class Command:
    """One checked command (see the module docstring for the verbs and their fields).

    Attributes
    ----------
    verb : str, one of VERBS
    args : dict, the verb's fields, checked and with their defaults filled in (JSON-ready: what is recorded)
    id : str, int or None, the client's id of the request, echoed in the reply
    """

    verb: str
    args: dict = field(default_factory=dict)
    id: object = None

    def to_json(self) -> dict:
        """The command as a JSON object (the recorded form; :func:`parse_command` reads it back)."""
        return {"verb": self.verb, **self.args}


def _name(doc: dict, key: str, where: str) -> str:
    value = doc.get(key)
    if not isinstance(value, str) or not value.strip() or len(value) > MAX_NAME:
        raise CommandError(f"{where}: field '{key}': expected a non-empty string of at most {MAX_NAME} characters, "
                           f"found {_show(value)}")
    return value


def _number(doc: dict, key: str, where: str, default: float | None, lo: float, hi: float,
            open_low: bool = False) -> float:
    value = doc.get(key, default)
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) \
        and (lo < value if open_low else lo <= value) and value <= hi
    if not ok:
        side = "(" if open_low else "["
        raise CommandError(f"{where}: field '{key}': expected a number in {side}{lo:g}, {hi:g}], found {_show(value)}")
    return float(value)


def _choice(doc: dict, key: str, where: str, choices: tuple[str, ...]) -> str:
    value = doc.get(key)
    if value not in choices:
        raise CommandError(f"{where}: field '{key}': expected one of {', '.join(choices)}, found {_show(value)}")
    return value


def _show(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _only(doc: dict, where: str, keys: tuple[str, ...]) -> None:
    unknown = sorted(set(doc) - {"verb", "id", *keys})
    if unknown:
        raise CommandError(f"{where}: field '{unknown[0]}': unknown; the fields are "
                           f"{', '.join(('verb', 'id', *keys))}")


def parse_command(doc: object, where: str = "command") -> Command:
    """The :class:`Command` of a JSON object; CommandError naming the field otherwise."""
    if not isinstance(doc, dict):
        raise CommandError(f"{where}: expected a JSON object, found {type(doc).__name__}")
    ident = doc.get("id")
    if ident is not None and not (isinstance(ident, (str, int)) and not isinstance(ident, bool)
                                  and len(str(ident)) <= MAX_NAME):
        raise CommandError(f"{where}: field 'id': expected a string or an integer, found {_show(ident)}")
    verb = _choice(doc, "verb", where, VERBS)
    args: dict = {}
    if verb == "expression":
        _only(doc, where, ("name", "action", "value", "fade", "seconds"))
        args["name"] = _name(doc, "name", where)
        args["action"] = action = _choice(doc, "action", where, EXPRESSION_ACTIONS)
        args["value"] = _number(doc, "value", where, 1.0, 0.0, 1.0)
        args["fade"] = _number(doc, "fade", where, DEFAULT_FADE_S, 0.0, MAX_FADE_S)
        if action == "for":
            args["seconds"] = _number(doc, "seconds", where, None, 0.0, MAX_FOR_S, open_low=True)
        elif "seconds" in doc:
            raise CommandError(f"{where}: field 'seconds': only with action 'for'")
    elif verb == "profile":
        _only(doc, where, ("name",))
        name = _name(doc, "name", where)
        if not _PROFILE_NAME.fullmatch(name):
            raise CommandError(f"{where}: field 'name': a profile name is letters, digits, '_', '-' and '.' "
                               f"(not first), never a path; found {_show(name)}")
        args["name"] = name
    elif verb == "record":
        _only(doc, where, ("action", "name"))
        args["action"] = _choice(doc, "action", where, RECORD_ACTIONS)
        if "name" in doc:
            name = _name(doc, "name", where)
            if args["action"] != "start" or not _RECORD_NAME.fullmatch(name):
                raise CommandError(f"{where}: field 'name': a recording's file name (letters, digits, '_', '-', "
                                   f"'.'), with action 'start' only; found {_show(name)}")
            args["name"] = name
    elif verb == "framing":
        _only(doc, where, ("framing", "zoom", "pan"))
        args["framing"] = _choice(doc, "framing", where, FRAMINGS) if "framing" in doc else None
        args["zoom"] = _number(doc, "zoom", where, 1.0, 0.0, MAX_ZOOM, open_low=True)
        pan = doc.get("pan", [0.0, 0.0])
        if not (isinstance(pan, list) and len(pan) == 2):
            raise CommandError(f"{where}: field 'pan': expected [x, y], found {_show(pan)}")
        args["pan"] = [_number({"pan": p}, "pan", where, None, -MAX_PAN, MAX_PAN) for p in pan]
    elif verb in ("subscribe", "view"):
        key = "rate" if verb == "subscribe" else "fps"
        _only(doc, where, (key,))
        args[key] = _number(doc, key, where, None, 0.0, MAX_RATE_HZ)
    else:
        _only(doc, where, ())
    return Command(verb, args, ident)


def parse_osc(address: str, params: list, token: str | None = None) -> Command:
    """The :class:`Command` of an OSC message under ``/facepuppet/``; CommandError otherwise.

    With ``token``, the first argument must be it (checked by the caller's comparison, see
    :func:`split_token`)."""
    where = f"OSC {address}"
    if not address.startswith(OSC_PREFIX):
        raise CommandError(f"{where}: not a control address (they start with {OSC_PREFIX})")
    parts = address[len(OSC_PREFIX):].split("/")
    strings = [p for p in params if isinstance(p, str)]
    numbers = [p for p in params if isinstance(p, (int, float)) and not isinstance(p, bool)]
    if len(strings) + len(numbers) != len(params):
        raise CommandError(f"{where}: arguments: expected strings and numbers only")
    doc: dict
    if parts[0] == "expression" and len(parts) == 2:
        doc = {"verb": "expression", "action": parts[1], "name": strings[0] if strings else None}
        if parts[1] == "for":
            if not numbers:
                raise CommandError(f"{where}: expected s name f seconds [f fade]")
            doc["seconds"], numbers = numbers[0], numbers[1:]
        if numbers:
            doc["fade"] = numbers[0]
    elif parts == ["calibrate"]:
        doc = {"verb": "calibrate"}
    elif parts == ["profile"]:
        doc = {"verb": "profile", "name": strings[0] if strings else None}
    elif parts[0] == "record" and len(parts) == 2:
        doc = {"verb": "record", "action": parts[1], **({"name": strings[0]} if strings else {})}
    elif parts == ["framing"]:
        doc = {"verb": "framing", **({"framing": strings[0]} if strings else {})}
        if numbers:
            doc["zoom"] = numbers[0]
        if len(numbers) >= 3:
            doc["pan"] = [numbers[1], numbers[2]]
    else:
        raise CommandError(f"{where}: unknown control address")
    return parse_command(doc, where)


def split_token(params: list) -> tuple[str | None, list]:
    """(the first argument when it is a string, the rest): an OSC message's token and its own arguments."""
    if params and isinstance(params[0], str):
        return params[0], list(params[1:])
    return None, list(params)
