"""What a phone sends, written from the published facts (PROTOCOLS.md §7, §8), not from the decoders.

* iFacialMocap (ifacialmocap.com "for developer"): UTF-8 text, ``name-value|`` items (v1) or
  ``name&value|`` (v2), values integers 0-100, then ``=head#rx,ry,rz,tx,ty,tz|rightEye#rx,ry,rz|
  leftEye#rx,ry,rz|``; names are ARKit's with the sides spelled ``_L``/``_R`` (``eyeBlink_L``;
  ``jawLeft``, ``mouthLeft`` are directions and keep their spelling).
* VTube Studio (DenchiSoft/VTubeStudioBlendshapeUDPReceiverTest): one JSON object per frame with
  ``Timestamp`` (Unix ms), ``Hotkey``, ``FaceFound``, ``Rotation``, ``Position``, ``EyeLeft``,
  ``EyeRight`` (``{"x","y","z"}``) and ``BlendShapes`` (``[{"k": PascalCase name, "v": 0-1}]``).
"""

from __future__ import annotations

import json

# Apple's 52 names, written out here (not imported) so the sender does not share the decoder's table.
ARKIT_52 = """eyeBlinkLeft eyeLookDownLeft eyeLookInLeft eyeLookOutLeft eyeLookUpLeft eyeSquintLeft eyeWideLeft
eyeBlinkRight eyeLookDownRight eyeLookInRight eyeLookOutRight eyeLookUpRight eyeSquintRight eyeWideRight
jawForward jawLeft jawRight jawOpen mouthClose mouthFunnel mouthPucker mouthLeft mouthRight mouthSmileLeft
mouthSmileRight mouthFrownLeft mouthFrownRight mouthDimpleLeft mouthDimpleRight mouthStretchLeft mouthStretchRight
mouthRollLower mouthRollUpper mouthShrugLower mouthShrugUpper mouthPressLeft mouthPressRight mouthLowerDownLeft
mouthLowerDownRight mouthUpperUpLeft mouthUpperUpRight browDownLeft browDownRight browInnerUp browOuterUpLeft
browOuterUpRight cheekPuff cheekSquintLeft cheekSquintRight noseSneerLeft noseSneerRight tongueOut""".split()
assert len(ARKIT_52) == 52
_DIRECTIONS = {"jawLeft", "jawRight", "mouthLeft", "mouthRight"}

IFM_START = b"iFacialMocap_sahuasouryya9218sauhuiayeta91555dy3719"  # the developer page's start payload


def ifm_name(arkit: str) -> str:
    """iFacialMocap's spelling of an ARKit name: ``eyeBlinkLeft`` -> ``eyeBlink_L``."""
    if arkit in _DIRECTIONS:
        return arkit
    if arkit.endswith("Left"):
        return arkit[:-4] + "_L"
    if arkit.endswith("Right"):
        return arkit[:-5] + "_R"
    return arkit


def ifm_frame(values: dict[str, float], head: tuple = (0, 0, 0, 0, 0, 0), right_eye: tuple | None = (0, 0, 0),
              left_eye: tuple | None = (0, 0, 0), version: int = 2, extra: str = "") -> bytes:
    """One iFacialMocap datagram: ``values`` by ARKit name in 0-100 (v2: may be negative), head and eyes."""
    sep = "&" if version == 2 else "-"
    items = [f"{ifm_name(k)}{sep}{v:g}" for k, v in values.items()]
    text = "|".join(items) + "|" + extra
    if head is not None:
        text += "=head#" + ",".join(f"{x:g}" for x in head) + "|"
    if right_eye is not None:
        text += "rightEye#" + ",".join(f"{x:g}" for x in right_eye) + "|"
    if left_eye is not None:
        text += "leftEye#" + ",".join(f"{x:g}" for x in left_eye) + "|"
    return text.encode("utf-8")


def vts_frame(values: dict[str, float], found: bool = True, rotation=(0.0, 0.0, 0.0), position=(0.0, 0.0, 0.0),
              eye_left=(0.0, 0.0, 0.0), eye_right=(0.0, 0.0, 0.0), timestamp: int = 1_700_000_000_000,
              hotkey: int = -1) -> bytes:
    """One VTube Studio tracking datagram: ``values`` by ARKit name (sent PascalCase), angles in degrees."""
    def vec(v):
        return None if v is None else {"x": v[0], "y": v[1], "z": v[2]}

    obj = {"Timestamp": timestamp, "Hotkey": hotkey, "FaceFound": found, "Rotation": vec(rotation),
           "Position": vec(position), "EyeLeft": vec(eye_left), "EyeRight": vec(eye_right),
           "BlendShapes": [{"k": k[0].upper() + k[1:], "v": v} for k, v in values.items()]}
    return json.dumps({k: v for k, v in obj.items() if v is not None}).encode("utf-8")
