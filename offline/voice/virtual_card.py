"""A private, clock-paced virtual sound card: PulseAudio's null sink, heard through ALSA by PortAudio.

A machine without a sound card (CI, a container) still has to run the microphone path for real: PortAudio
opening a capture device by name, its callback thread, blocks arriving at the pace of a real clock. ALSA's
``file`` or ``null`` PCMs deliver samples as fast as they are read, which tells nothing about timing, so the
card is a PulseAudio ``module-null-sink``: the server renders it on the system clock, and its ``.monitor``
source hands back, in real time, whatever is played into the sink.

:class:`VirtualSoundCard` starts its own ``pulseaudio`` (no daemon, no default script, anonymous access on
a socket in a private folder, its HOME there too, so it neither finds nor disturbs another server) and
writes that folder's ``.asoundrc`` with two ALSA PCMs of the ``pulse`` plugin (libasound2-plugins) naming
the server's socket: ``NAME`` captures the sink's monitor (what ``--audio NAME`` opens) and ``NAME_play``
plays into the sink. A process sees them when its HOME is the card's folder (:attr:`env`); PortAudio reads
the ALSA configuration when it initialises, so :meth:`VirtualSoundCard.visible` re-initialises sounddevice
in a process that had it loaded already. Stopping the card ends its server and removes nothing else.
"""

from __future__ import annotations

import logging
import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from facepuppet.runtime.inputs.audio import AudioUnavailable

logger = logging.getLogger(__name__)

PROGRAMS = ("pulseaudio",)
PULSE_PLUGIN = "libasound_module_pcm_pulse.so"
START_TIMEOUT_S = 20.0


def missing() -> str | None:
    """Why a virtual card cannot be had on this machine, in words (None when it can)."""
    absent = [p for p in PROGRAMS if shutil.which(p) is None]
    if absent:
        return f"{', '.join(absent)} not installed (Debian: apt-get install pulseaudio libasound2-plugins)"
    if not any(Path(d).glob(f"*/alsa-lib/{PULSE_PLUGIN}") or Path(d, "alsa-lib", PULSE_PLUGIN).exists()
               for d in ("/usr/lib", "/usr/lib64", "/usr/local/lib")):
        return f"ALSA's pulse plugin ({PULSE_PLUGIN}) not installed (Debian: apt-get install libasound2-plugins)"
    return None


class CardUnavailable(AudioUnavailable):
    """The virtual card could not be started; the message says why (a missing device, as the microphone's)."""


class VirtualSoundCard:
    """A private PulseAudio null sink and its monitor as ALSA devices (see the module docstring).

    Parameters
    ----------
    folder : str or Path or None, where the server's socket, HOME and log go (None: a temporary folder,
        removed by :meth:`stop`)
    name : str, the capture device's ALSA name (``NAME_play`` is the playing one)
    rate : int, Hz, the sink's sample rate (PortAudio's default rate for the pulse PCMs, so nothing resamples)
    """

    def __init__(self, folder: str | os.PathLike | None = None, name: str = "vcard", rate: int = 44100) -> None:
        if not name.isidentifier():
            raise ValueError(f"virtual card name: expected letters, digits and _, got {name!r}")
        self.name = name
        self.rate = int(rate)
        self._own = folder is None
        self.folder = Path(tempfile.mkdtemp(prefix="fp-vcard-")) if folder is None else Path(folder)
        self.home = self.folder / "home"
        self.socket = self.folder / "native"
        self.log_path = self.folder / "pulseaudio.log"
        self.proc: subprocess.Popen | None = None

    @property
    def server(self) -> str:
        return f"unix:{self.socket}"

    @property
    def play_device(self) -> str:
        return f"{self.name}_play"

    @property
    def env(self) -> dict[str, str]:
        """The environment of a process that uses the card: this one's, with HOME and the server set."""
        return {**os.environ, "HOME": str(self.home), "PULSE_SERVER": self.server,
                "PULSE_RUNTIME_PATH": str(self.folder / "runtime")}

    def _asoundrc(self) -> str:
        def pcm(name: str, device: str, what: str) -> str:
            return (f'pcm.{name} {{\n    type pulse\n    server "{self.server}"\n    device "{device}"\n'
                    f'    hint {{ show on description "facepuppet virtual sound card ({what})" }}\n}}\n')
        return (pcm(self.name, f"{self.name}.monitor", "capture: what is played into the sink")
                + pcm(self.play_device, self.name, "playback into the sink"))

    def start(self) -> VirtualSoundCard:
        """Start the server and wait until its socket answers; CardUnavailable (with the server's log) if not."""
        why = missing()
        if why is not None:
            raise CardUnavailable(f"no virtual sound card: {why}")
        self.home.mkdir(parents=True, exist_ok=True)
        (self.folder / "runtime").mkdir(exist_ok=True)
        (self.home / ".asoundrc").write_text(self._asoundrc())
        args = [shutil.which("pulseaudio"), "--daemonize=no", "--exit-idle-time=-1", "-n", "--use-pid-file=no",
                "--disable-shm=yes", "--log-target=stderr",
                f"--load=module-null-sink sink_name={self.name} rate={self.rate} channels=1",
                f"--load=module-native-protocol-unix auth-anonymous=1 socket={self.socket}"]
        env = {**self.env, "XDG_RUNTIME_DIR": str(self.folder / "runtime")}
        with open(self.log_path, "wb") as log:
            self.proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=log, stderr=log, env=env,
                                         cwd=self.folder)
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                break
            if self._answers():
                logger.info("virtual sound card %s: pulseaudio %d on %s", self.name, self.proc.pid, self.socket)
                return self
            time.sleep(0.05)
        self.stop()
        tail = self.log_path.read_text(errors="replace")[-2000:] if self.log_path.exists() else ""
        raise CardUnavailable(f"no virtual sound card: pulseaudio did not answer on {self.socket} within "
                              f"{START_TIMEOUT_S:g} s; its log:\n{tail}")

    def _answers(self) -> bool:
        if not self.socket.exists():
            return False
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            try:
                s.connect(str(self.socket))
            except OSError:
                return False
        return True

    def stop(self) -> None:
        """End the server (SIGTERM, then SIGKILL after 5 s); remove the folder if the card made it."""
        proc, self.proc = self.proc, None
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        if self._own:
            shutil.rmtree(self.folder, ignore_errors=True)

    def __enter__(self) -> VirtualSoundCard:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


@contextmanager
def visible(card: VirtualSoundCard) -> Iterator[object]:
    """This process sees the card's devices through sounddevice while inside (HOME and PULSE_SERVER set,
    PortAudio re-initialised on the way in and out); yields the sounddevice module."""
    saved = {k: os.environ.get(k) for k in ("HOME", "PULSE_SERVER", "PULSE_RUNTIME_PATH")}
    os.environ.update({k: card.env[k] for k in saved})
    had = "sounddevice" in sys.modules
    try:
        import sounddevice as sd

        if had:
            sd._terminate()
            sd._initialize()
        yield sd
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        if "sounddevice" in sys.modules:
            sd = sys.modules["sounddevice"]
            sd._terminate()
            sd._initialize()
