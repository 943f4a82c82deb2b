"""Small VRM-like characters built in code: morphs with their own names, expressions bound to them.

Until the glTF reader builds real ones, these stand in for a VRM avatar: a VRM-preset-only one
(``blink_left``, ``ah``, ... morphs and the VRM 0.x presets bound to them, like Low-Poly Godette) and a
perfect-sync one (ARKit-named morphs).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.model.character import Character
from facepuppet.runtime.model.character_parts import OVERRIDES, Expressions

from helpers.small_characters import sphere_character

#: The morphs of the preset-only character (Godette's face morph names, and an angry brow and a smile).
PRESET_MORPHS = ("blink_left", "blink_right", "ah", "ih", "uu", "ee", "oh", "look_up", "look_down",
                 "look_left", "look_right", "angled_eyebrows", "smile", "HideBlush")

#: (name, preset, ((morph, bind weight), ...)) of the preset-only character: the bind weights are not all 1,
#: so a test can tell a bind weight from a pass-through.
PRESET_EXPRESSIONS = (
    ("Blink", "Blink", (("blink_left", 1.0), ("blink_right", 1.0))),
    ("Blink_L", "Blink_L", (("blink_left", 1.0),)),
    ("Blink_R", "Blink_R", (("blink_right", 1.0),)),
    ("A", "A", (("ah", 1.0),)),
    ("I", "I", (("ih", 0.8),)),
    ("U", "U", (("uu", 1.0),)),
    ("E", "E", (("ee", 1.0),)),
    ("O", "O", (("oh", 0.6), ("ah", 0.5))),
    ("Joy", "Joy", (("smile", 1.0),)),
    ("Angry", "Angry", (("angled_eyebrows", 0.5),)),
    ("Sorrow", "Sorrow", ()),
    ("Fun", "Fun", (("smile", 0.5),)),
    ("LookUp", "LookUp", (("look_up", 1.0),)),
    ("LookDown", "LookDown", (("look_down", 1.0),)),
    ("LookLeft", "LookLeft", (("look_left", 1.0),)),
    ("LookRight", "LookRight", (("look_right", 1.0),)),
    ("Neutral", "Neutral", ()),
    ("HideBlush", "", (("HideBlush", 1.0),)),
)


def expressions_of(shape_names: Sequence[str], table, flags: dict | None = None) -> Expressions:
    """Expressions from ``(name, preset, ((shape, weight), ...))`` rows; ``flags`` name -> (is_binary,
    override blink, override lookAt, override mouth) with the override codes spelled ("block", "blend")."""
    index = {s: i for i, s in enumerate(shape_names)}
    offsets, shapes, weights, rows = [0], [], [], []
    for name, _, binds in table:
        for s, w in binds:
            shapes.append(index[s])
            weights.append(w)
        offsets.append(len(shapes))
        binary, *over = (flags or {}).get(name, (False, "none", "none", "none"))
        rows.append([int(binary), *(OVERRIDES[o] for o in over)])
    return Expressions(tuple(r[0] for r in table), tuple(r[1] for r in table), np.array(offsets, np.int64),
                       np.array(shapes, np.uint32), np.array(weights, np.float32), np.array(rows, np.int32))


def morph_character(morphs: Sequence[str]) -> Character:
    """The sphere head with these shapes, each moving its own band of vertices by 1 cm along +z."""
    base = sphere_character(with_hidden=False)
    v = base.vertices
    bands = np.array_split(np.argsort(v[:, 1], kind="stable"), len(morphs))
    shapes = {}
    for name, band in zip(morphs, bands):
        d = np.zeros_like(v)
        d[band, 2] = 1.0
        shapes[name] = d
    from helpers.small_characters import make_character

    return make_character(v, base.triangles, base.triangle_material, base.vertex_color, base.material_names,
                          base.material_params, shapes)


def preset_character(flags: dict | None = None, table=PRESET_EXPRESSIONS) -> Character:
    """A VRM-preset-only avatar: :data:`PRESET_MORPHS` and :data:`PRESET_EXPRESSIONS` (VRM 0.x: no overrides)."""
    c = morph_character(PRESET_MORPHS)
    return c.with_parts(expressions=expressions_of(c.shape_names, table, flags))


#: A perfect-sync avatar's morphs: ARKit names in the ``_L`` style of many rigs, and a Blink expression on them.
SYNC_MORPHS = ("eyeBlink_L", "eyeBlink_R", "jawOpen", "mouthFunnel", "mouthPucker", "mouthSmile_L",
               "mouthSmile_R", "browInnerUp")


def sync_character() -> Character:
    """ARKit-named morphs plus VRM presets Blink (both eyelids) and A (the jaw at 0.7) bound to them."""
    c = morph_character(SYNC_MORPHS)
    table = (("Blink", "Blink", (("eyeBlink_L", 1.0), ("eyeBlink_R", 1.0))), ("A", "A", (("jawOpen", 0.7),)))
    return c.with_parts(expressions=expressions_of(c.shape_names, table))
