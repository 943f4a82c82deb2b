"""The ``virtual_sound_card`` fixture: a private PulseAudio null sink heard as the ALSA device ``vcard``.

Each test gets its own server on its own socket, HOME and folder (under tmp_path), started by the fixture and
always stopped by it; the test skips, saying why, only when pulseaudio, pacat or ALSA's pulse plugin is not
installed (a server that is installed but fails to start fails the test). A process that should see the card
runs with ``card.env``; :func:`play` plays a WAV into it with PulseAudio's own ``pacat``, a player that is no
part of facepuppet (tests/conftest.py loads this module as a plugin).
"""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from facepuppet.offline.voice.virtual_card import VirtualSoundCard, missing


@pytest.fixture
def virtual_sound_card(tmp_path: Path) -> Iterator[VirtualSoundCard]:
    why = missing() or (None if shutil.which("pacat") else "pacat not installed (Debian: pulseaudio-utils)")
    if why is not None:
        pytest.skip(f"no virtual sound card: {why}")
    card = VirtualSoundCard(tmp_path / "vcard")
    try:
        card.start()
        yield card
    finally:
        card.stop()


def play(card: VirtualSoundCard, wav: Path) -> subprocess.Popen:
    """Start playing ``wav`` into the card's sink (pacat, in real time); the caller waits for it."""
    return subprocess.Popen(["pacat", "--playback", f"--server={card.server}", f"--device={card.name}",
                             "--file-format=wav", str(wav)], env=card.env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
