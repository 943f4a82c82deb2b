"""Blendshape names the VMC/VRM world expects, and the default map from ARKit's 52 channels to them.

One table for everything that speaks to or reads a VRM avatar: ``--vmc-out``
(:mod:`facepuppet.runtime.live.vmc_out`) and the glTF/VRM import (issue 13).

**Perfect sync** (PROTOCOLS.md §1): the 52 ARKit shapes of
:data:`~facepuppet.runtime.mapping.channels.ARKIT_NAMES` spelled in PascalCase
(``EyeBlinkLeft`` … ``TongueOut``), case-sensitive: :data:`PERFECT_SYNC_NAMES`.

**Folding a rig's channels back into ARKit's 52** (:func:`fold_to_arkit`):

* a channel whose canonical key is the ARKit name (``eyeBlink_L``,
  ``EyeBlinkLeft``, ``eyeBlinkLeft``) is sent as it is;
* ARKit's unsided shapes that a rig splits (ICT-FaceKit's ``browInnerUp_L/_R``,
  ``cheekPuff_L/_R``) are folded by the **max** of the two sides: a
  symmetric pose gives the same value as the mean would, and a one-sided
  raise keeps its full size instead of being halved. A rig with only one side
  sends that side;
* a sided ARKit channel the rig has only unsided (``eyeBlink``) takes that value
  on both sides;
* an ARKit channel the rig has no shape for is sent as 0 (the rig cannot make
  that motion, so a perfect-sync avatar should not either);
* every other channel of the rig (``cheekRaiser_L``, ``PupilDilate_R``) is an
  *extra*: not ARKit, sent by ``--vmc-extra`` only, under its PascalCase name.

**VRM 0.x presets** (:data:`VRM0_PRESETS`, :func:`vrm0_from_arkit`), so an
avatar without perfect sync still blinks, looks and talks. Each preset is a
weighted sum of ARKit channels clipped to [0, 1] (:data:`VRM0_FROM_ARKIT`; a
pair written ``mouthSmile*`` means the mean of its Left and Right), except the
blinks: a VRM avatar adds ``Blink``, ``Blink_L`` and ``Blink_R``, so they are
split so that each eye closes exactly as much as ARKit says:

* ``Blink = min(eyeBlinkLeft, eyeBlinkRight)``,
* ``Blink_L = eyeBlinkLeft - Blink``, ``Blink_R = eyeBlinkRight - Blink``.

======================  =====================================================
preset                  from ARKit (sum, clipped to [0, 1])
======================  =====================================================
``A``                   jawOpen − 0.5 mouthFunnel − 0.5 mouthPucker
``I``                   mouthStretch* − 0.5 mouthPucker
``U``                   mouthPucker − 0.5 jawOpen
``E``                   0.5 mouthLowerDown* + 0.5 mouthStretch* − 0.5 mouthFunnel
``O``                   mouthFunnel
``Joy``                 mouthSmile*
``Angry``               browDown*
``Sorrow``              0.5 browInnerUp + 0.5 mouthFrown*
``Fun``                 cheekSquint*
``LookUp``              eyeLookUp*
``LookDown``            eyeLookDown*
``LookLeft``            0.5 eyeLookOutLeft + 0.5 eyeLookInRight (the gaze to the avatar's own left)
``LookRight``           0.5 eyeLookInLeft + 0.5 eyeLookOutRight
``Neutral``             always 0
======================  =====================================================

The vowels are a plain default, not a phoneme recogniser: open jaw reads as A,
rounded lips as O and U, spread lips as I and E. :data:`VRM1_FROM_VRM0`
gives the VRM 1.0 names of the presets (the conversion a VRM 1.0 receiver
applies, PROTOCOLS.md §1).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from facepuppet.runtime.mapping.channels import ARKIT_NAMES, canonical, pascal, split_side

#: ARKit's 52 shapes in Apple's order, in the PascalCase of VMC perfect sync.
PERFECT_SYNC_NAMES: tuple[str, ...] = tuple(pascal(n) for n in ARKIT_NAMES)

#: The VRM 0.x blend shape presets facepuppet sends (``Unknown`` is not a motion and is left out).
VRM0_PRESETS: tuple[str, ...] = (
    "Blink", "Blink_L", "Blink_R", "A", "I", "U", "E", "O",
    "Joy", "Angry", "Sorrow", "Fun", "LookUp", "LookDown", "LookLeft", "LookRight", "Neutral",
)

#: VRM 1.0 expression name of each VRM 0.x preset.
VRM1_FROM_VRM0: dict[str, str] = {
    "Blink": "blink", "Blink_L": "blinkLeft", "Blink_R": "blinkRight",
    "A": "aa", "I": "ih", "U": "ou", "E": "ee", "O": "oh",
    "Joy": "happy", "Angry": "angry", "Sorrow": "sad", "Fun": "relaxed",
    "LookUp": "lookUp", "LookDown": "lookDown", "LookLeft": "lookLeft", "LookRight": "lookRight",
    "Neutral": "neutral",
}

#: The linear presets: preset -> ((ARKit name, or a pair written "name*" for the mean of its sides), weight).
#: The blinks are not here (see the module doc); Neutral is the empty sum.
VRM0_FROM_ARKIT: dict[str, tuple[tuple[str, float], ...]] = {
    "A": (("jawOpen", 1.0), ("mouthFunnel", -0.5), ("mouthPucker", -0.5)),
    "I": (("mouthStretch*", 1.0), ("mouthPucker", -0.5)),
    "U": (("mouthPucker", 1.0), ("jawOpen", -0.5)),
    "E": (("mouthLowerDown*", 0.5), ("mouthStretch*", 0.5), ("mouthFunnel", -0.5)),
    "O": (("mouthFunnel", 1.0),),
    "Joy": (("mouthSmile*", 1.0),),
    "Angry": (("browDown*", 1.0),),
    "Sorrow": (("browInnerUp", 0.5), ("mouthFrown*", 0.5)),
    "Fun": (("cheekSquint*", 1.0),),
    "LookUp": (("eyeLookUp*", 1.0),),
    "LookDown": (("eyeLookDown*", 1.0),),
    "LookLeft": (("eyeLookOutLeft", 0.5), ("eyeLookInRight", 0.5)),
    "LookRight": (("eyeLookInLeft", 0.5), ("eyeLookOutRight", 0.5)),
    "Neutral": (),
}

_ARKIT_INDEX = {name: i for i, name in enumerate(ARKIT_NAMES)}


def _preset_matrix() -> np.ndarray:
    m = np.zeros((len(VRM0_PRESETS), len(ARKIT_NAMES)))
    for p, preset in enumerate(VRM0_PRESETS):
        for name, weight in VRM0_FROM_ARKIT.get(preset, ()):
            if name.endswith("*"):
                for side in ("Left", "Right"):
                    m[p, _ARKIT_INDEX[name[:-1] + side]] += weight / 2
            else:
                m[p, _ARKIT_INDEX[name]] += weight
    m.setflags(write=False)
    return m


#: (17, 52) float64: row p of it, times the ARKit values, is preset p before clipping (zero rows for the blinks).
PRESET_MATRIX: np.ndarray = _preset_matrix()
_BLINK = (VRM0_PRESETS.index("Blink"), VRM0_PRESETS.index("Blink_L"), VRM0_PRESETS.index("Blink_R"))
_EYE_BLINK = (_ARKIT_INDEX["eyeBlinkLeft"], _ARKIT_INDEX["eyeBlinkRight"])


def vrm0_from_arkit(arkit: np.ndarray) -> np.ndarray:
    """VRM 0.x preset values from ARKit values.

    Parameters
    ----------
    arkit : ndarray of shape (..., 52), float, in ARKit's order (NaN counts as 0)

    Returns
    -------
    ndarray of shape (..., 17), float64, in :data:`VRM0_PRESETS` order, each in [0, 1]
    """
    a = np.clip(np.nan_to_num(np.asarray(arkit, dtype=np.float64), nan=0.0), 0.0, 1.0)
    if a.shape[-1] != len(ARKIT_NAMES):
        raise ValueError(f"vrm0_from_arkit: expected {len(ARKIT_NAMES)} ARKit values, got {a.shape[-1]}")
    out = np.clip(a @ PRESET_MATRIX.T, 0.0, 1.0)
    left, right = a[..., _EYE_BLINK[0]], a[..., _EYE_BLINK[1]]
    both = np.minimum(left, right)
    out[..., _BLINK[0]], out[..., _BLINK[1]], out[..., _BLINK[2]] = both, left - both, right - both
    return out


def fold_to_arkit(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Where each of ARKit's 52 channels comes from among a rig's channels (see the module doc).

    Parameters
    ----------
    names : sequence of n str, the rig's channel names, any spelling

    Returns
    -------
    first, second : ndarray of shape (52,), int, indices into the rig's values extended by one 0 at
        index n: ARKit channel k is ``max(values[first[k]], values[second[k]])`` (the same index twice
        for a direct match, n for a channel the rig lacks)
    extras : tuple of int, the rig's channels that are not ARKit's (in the rig's order)
    """
    n = len(names)
    index: dict[str, int] = {}
    for i, name in enumerate(names):
        index.setdefault(canonical(name), i)
    first = np.full(len(ARKIT_NAMES), n, dtype=np.intp)
    second = np.full(len(ARKIT_NAMES), n, dtype=np.intp)
    used: set[int] = set()
    for k, key in enumerate(ARKIT_NAMES):
        base, side = split_side(key)
        if key in index:
            pair = (index[key], index[key])
        elif side is None and (key + "Left" in index or key + "Right" in index):
            # an unsided ARKit shape the rig splits: the max of its sides
            sides = [index[key + s] for s in ("Left", "Right") if key + s in index]
            pair = (sides[0], sides[-1])
        elif side is not None and base in index:
            pair = (index[base], index[base])  # the rig has one unsided shape for a sided ARKit pair
        else:
            continue
        first[k], second[k] = pair
        used.update(pair)
    extras = tuple(i for i in range(n) if i not in used and canonical(names[i]) in index
                   and index[canonical(names[i])] == i)
    return first, second, extras
