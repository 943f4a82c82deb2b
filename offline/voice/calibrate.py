"""``facepuppet calibrate-voice``: the user's A, I, U, E, O (and silence) -> a vowel profile (TOML).

Each vowel comes from a WAV (``--wav A=a.wav``, one per vowel, a few seconds of it held) or, with ``--from-mic
SECONDS``, from the microphone, prompted vowel by vowel. The profile is built by the runtime
(:func:`~facepuppet.runtime.voice.vowels.build_profile`), so what ``run --voice profile.toml`` matches is what
was measured here; the command prints how many of each take's voiced hops the profile recognises.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.inputs.audio import AudioUnavailable, read_wav
from facepuppet.runtime.voice.vowels import VOWELS, build_profile, voiced_hops

TAKES = (*VOWELS, "silence")


def parse_take(text: str) -> tuple[str, Path]:
    """``A=a.wav`` -> ("A", Path("a.wav")) for ``--wav``."""
    name, sep, path = text.partition("=")
    key = name.strip().upper() if name.strip().lower() != "silence" else "silence"
    if not sep or key not in TAKES or not path:
        raise argparse.ArgumentTypeError(f"expected VOWEL=FILE.wav with VOWEL one of {', '.join(TAKES)}, got {text!r}")
    return key, Path(path)


def record_takes(seconds: float, device: int | str | None, log: Callable[[str], None]) -> tuple[dict, int]:
    """Each take from the microphone, prompted; AudioUnavailable when there is none."""
    try:
        import sounddevice as sd
    except (ImportError, OSError) as exc:
        raise AudioUnavailable(f"no audio: sounddevice/PortAudio is not available ({exc}); pass the takes as "
                               "--wav VOWEL=FILE.wav") from None
    try:
        rate = int(sd.query_devices(device, "input")["default_samplerate"])
        takes = {}
        for name in TAKES:
            log(f"calibrate-voice: {'stay quiet' if name == 'silence' else f'hold the vowel {name}'} for "
                f"{seconds:g} s ...")
            takes[name] = sd.rec(int(seconds * rate), samplerate=rate, channels=1, device=device, blocking=True)[:, 0]
    except (ValueError, sd.PortAudioError, OSError) as exc:
        raise AudioUnavailable(f"no audio: could not record from the input device ({exc}); pass the takes as "
                               "--wav VOWEL=FILE.wav") from None
    return {k: np.asarray(v, np.float64) for k, v in takes.items()}, rate


def calibrate_voice_command(args: argparse.Namespace, log: Callable[[str], None] = print) -> int:
    if args.from_mic is not None:
        if args.wav:
            raise UsageError("calibrate-voice: --from-mic or --wav, not both")
        if not 0.5 <= args.from_mic <= 30:
            raise UsageError(f"--from-mic: expected 0.5..30 seconds per take, got {args.from_mic:g}")
        takes, rate = record_takes(args.from_mic, args.device, log)
    else:
        given = dict(args.wav or ())
        missing = [v for v in VOWELS if v not in given]
        if missing:
            raise UsageError(f"calibrate-voice: no --wav for {', '.join(missing)} (give --wav A=a.wav ... for each "
                             "of A I U E O, or --from-mic SECONDS)")
        takes, rate = {}, None
        for name, path in given.items():
            x, r = read_wav(path)
            if rate is not None and r != rate:
                raise UsageError(f"--wav {name}={path}: {r} Hz; the other takes are {rate} Hz (give one rate)")
            takes[name], rate = x, r
    try:
        profile, report = build_profile({v: takes[v] for v in VOWELS}, rate, takes.get("silence"))
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    for i, v in enumerate(VOWELS):
        X = voiced_hops(profile, takes[v], rate)
        recognised = float((profile.classify(X) == i).mean()) if len(X) else float("nan")
        log(f"  {v}: {report[v]['hops']} voiced hops at {report[v]['level_db']:.1f} dBFS, "
            f"{recognised:.0%} recognised as {v}")
    out = profile.save(args.output)
    log(f"{out}: vowel profile ({len(VOWELS)} vowels{', silence' if profile.silence is not None else ''}); "
        f"openness {profile.floor_db:.1f}..{profile.ceiling_db:.1f} dBFS; run --voice {out}")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "calibrate-voice",
        help="the user's A I U E O (and silence) -> a vowel profile for run --voice PROFILE.toml",
        description="Build MFCC templates of the user's own vowels (the uLipSync method) from WAV files or the "
                    "microphone; run --voice PROFILE.toml then drives the VRM vowel expressions and their ARKit "
                    "mouth shapes, the openness from the voice level.",
    )
    p.add_argument("--wav", type=parse_take, action="append", metavar="VOWEL=FILE.wav",
                   help="one take per vowel (A, I, U, E, O) and optionally silence, a few seconds each")
    p.add_argument("--from-mic", type=float, metavar="SECONDS", help="record each take from the microphone instead")
    p.add_argument("--device", default=None, help="input device for --from-mic (default: the system's)")
    p.add_argument("-o", "--output", type=Path, required=True, help="profile to write (.toml)")
    p.set_defaults(func=calibrate_voice_command)
