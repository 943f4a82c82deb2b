"""A microphone block that arrives further behind the capture clock than the stated bound is dropped unread
and counted, so the voice never moves the mouth seconds after the sound: the blocks are fed through the
callback's own signature (PortAudio's ``time_info``) to a real, not started, stream on the virtual card;
a run listening to the card reports the bound and the figures, and reads no block beyond it."""

from __future__ import annotations

import dataclasses
import logging
import re
import subprocess
import sys
import tracemalloc
from types import SimpleNamespace

import numpy as np
import pytest

from facepuppet.runtime.inputs.audio import MicLevel
from facepuppet.runtime.inputs.capture_lag import FLOOR_CAP_S, FLOOR_RISE, MAX_LAG_S
from facepuppet.runtime.voice.source import MicVoice

from facepuppet.offline.voice.virtual_card import visible
from helpers.small_characters import grid_face
from helpers.virtual_sound_card import play
from helpers.voice_tables import small_table, vowel_buzz, write_wav

SHAPES = ("jawOpen", "mouthFunnel", "browInnerUp", "eyeLookIn_L", "cornerBump")
STREAM_T = 100.0  # PortAudio's stream clock (s) at the blocks fed below


def _times(lag_s: float) -> SimpleNamespace:
    """What PortAudio's callback receives as ``time_info`` for a block captured ``lag_s`` ago."""
    return SimpleNamespace(inputBufferAdcTime=STREAM_T - lag_s, currentTime=STREAM_T, outputBufferDacTime=0.0)


def _block(mic: MicLevel, loud: bool) -> np.ndarray:
    n = int(mic.stream.blocksize)
    x = (0.5 * np.sin(np.arange(n) * 0.3)) if loud else np.zeros(n)
    return x.astype(np.float32)[:, None]


@pytest.fixture
def mic(virtual_sound_card):
    with visible(virtual_sound_card):
        level = MicLevel(virtual_sound_card.name, start=False)
        try:
            yield level
        finally:
            level.close()


def test_stale_blocks_are_dropped_unread_counted_and_said_once(mic, caplog):
    voice = MicVoice(mic, small_table("ridge"))
    assert MAX_LAG_S <= mic.lag.bound_s <= MAX_LAG_S + FLOOR_CAP_S  # the stream's stated latency, within the cap
    assert mic.counters["bound_ms"] == int(mic.lag.bound_s * 1000)
    loud = _block(mic, loud=True)
    with caplog.at_level(logging.WARNING, logger="facepuppet.runtime.inputs.capture_lag"):
        rise = FLOOR_RISE * len(loud) / mic.meter.sample_rate  # the most the bound moves in one block
        for lag in (2.0, 5.0):  # a backlog: loud blocks seconds old
            mic._callback(loud, len(loud), _times(lag), 0)
        mic._callback(loud, len(loud), _times(mic.lag.bound_s + rise + 0.001), 0)  # and one just past the bound
    assert mic.level() == mic.meter.floor_db  # none of them was read: the level is still silence's
    assert voice.voice.hops == 0  # nor reached the voice
    c = dict(mic.counters)
    assert (c["blocks"], c["read"], c["stale_dropped"], c["max_stale_lag_ms"]) == (3, 0, 3, 5000)
    said = [r for r in caplog.records if "behind the capture clock" in r.getMessage()]
    assert len(said) == 1 and "2000 ms" in said[0].getMessage(), [r.getMessage() for r in caplog.records]

    hop_blocks = 1 + voice.voice.features.hop_n // len(loud)
    for _ in range(hop_blocks):  # fresh blocks: read, a hop evaluated
        mic._callback(loud, len(loud), _times(0.005), 0)
    assert mic.level() > -20.0
    assert voice.voice.hops >= 1
    c = dict(mic.counters)
    assert c["read"] == hop_blocks and c["stale_dropped"] == 3
    assert c["max_read_lag_ms"] in (4, 5) and c["floor_ms"] <= 5 + rise * 1000  # the floor follows a lower lag
    mic._callback(loud, len(loud), _times(3.0), 0)  # a later stale block: counted, not said again
    assert mic.counters["stale_dropped"] == 4
    assert len([r for r in caplog.records if "behind the capture clock" in r.getMessage()]) == 1


def test_a_standing_latency_is_read_up_to_the_cap_and_a_backlog_on_top_of_it_is_dropped(mic):
    quiet = _block(mic, loud=False)
    block_s = len(quiet) / mic.meter.sample_rate
    mic._callback(quiet, len(quiet), _times(0.0), 0)
    for _ in range(int(3.0 / block_s)):  # 3 s of a device whose blocks all come 90 ms late
        mic._callback(quiet, len(quiet), _times(0.09), 0)
    c = dict(mic.counters)
    rise_s = 0.09 - MAX_LAG_S  # dropped only until the floor has risen this far, at FLOOR_RISE s per s
    assert c["stale_dropped"] <= rise_s / FLOOR_RISE / block_s + 1, c
    assert c["floor_ms"] == 90 and c["max_read_lag_ms"] <= c["bound_ms"], c
    for _ in range(50):  # a stall's backlog on top of it: 0.5 s old, dropped, and the floor stays
        mic._callback(quiet, len(quiet), _times(0.5), 0)
    c2 = dict(mic.counters)
    assert c2["stale_dropped"] == c["stale_dropped"] + 50 and c2["max_read_lag_ms"] == c["max_read_lag_ms"]
    assert c2["floor_ms"] <= 90 + 50 * block_s * FLOOR_RISE * 1000 + 1
    for _ in range(int(20.0 / block_s)):  # a standing 0.5 s: never forgiven past the cap
        mic._callback(quiet, len(quiet), _times(0.5), 0)
    c3 = dict(mic.counters)
    assert c3["read"] == c2["read"] and c3["floor_ms"] == int(FLOOR_CAP_S * 1000)
    assert c3["bound_ms"] == int((FLOOR_CAP_S + MAX_LAG_S) * 1000) and c3["max_read_lag_ms"] <= c3["bound_ms"]


def test_a_host_that_gives_no_times_drops_nothing(mic):
    quiet = _block(mic, loud=False)
    none = SimpleNamespace(inputBufferAdcTime=0.0, currentTime=0.0, outputBufferDacTime=0.0)
    for _ in range(5):
        mic._callback(quiet, len(quiet), none, 0)
    assert (mic.counters["read"], mic.counters["stale_dropped"]) == (5, 0)


def test_dropping_stale_blocks_allocates_nothing_that_stays(mic):
    MicVoice(mic, small_table("ridge"))
    loud = _block(mic, loud=True)
    stale = _times(4.0)
    for _ in range(10):  # the one log line and any first-call caches
        mic._callback(loud, len(loud), stale, 0)
    tracemalloc.start()
    try:
        before = tracemalloc.take_snapshot()
        for _ in range(2000):
            mic._callback(loud, len(loud), stale, 0)
        after = tracemalloc.take_snapshot()
    finally:
        tracemalloc.stop()
    grown = sum(s.size_diff for s in after.compare_to(before, "filename") if s.size_diff > 0)
    assert grown < 4096, grown  # not a byte per block
    assert mic.counters["stale_dropped"] == 2010


@pytest.mark.gl
@pytest.mark.slow
def test_a_run_on_the_card_reads_no_block_beyond_the_bound_and_reports_it(tmp_path, virtual_sound_card):
    card = virtual_sound_card
    table = small_table("ridge").save(tmp_path / "voice.npz")
    char = dataclasses.replace(grid_face(extra=True), shape_names=SHAPES).save(
        tmp_path / "c.npz")
    wav = tmp_path / "voice.wav"
    rate = 16000
    write_wav(wav, np.concatenate([np.zeros(rate), vowel_buzz(2.0, rate, on_off_hz=1.0), np.zeros(rate)]), rate)
    players = []

    proc = subprocess.Popen([sys.executable, "-m", "facepuppet", "run", "-c", str(char), "--input", "audio", "--voice",
                             str(table), "--audio", card.name, "--headless", "--size", "48x40", "--duration", "6",
                             "--stats"], env=card.env, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    lines = []
    try:
        for line in proc.stdout:  # play once the microphone is open, while the run listens
            lines.append(line)
            if line.startswith("stages:") and not players:
                players.append(play(card, wav))
        code = proc.wait(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        for player in players:
            player.wait(timeout=60)
    out = "".join(lines)
    assert players, out
    assert code == 0, out
    summary = re.search(r"run: microphone: (\d+) of (\d+) blocks read, (\d+) dropped as stale \(the stalest (\d+) ms "
                        r"behind the capture clock\); the most a block read lagged (\d+) ms \(bound: 60 ms past the "
                        r"standing latency, at most 160 ms; at the end (\d+) ms\)", out)
    assert summary, out
    read, blocks, dropped, stalest, read_lag, bound_ms = map(int, summary.groups())
    assert read + dropped == blocks and read > 0, out
    assert read_lag <= (MAX_LAG_S + FLOOR_CAP_S) * 1000, out  # no block read further behind the capture clock
    assert dropped == 0 or stalest > MAX_LAG_S * 1000, out
    assert MAX_LAG_S * 1000 <= bound_ms <= (MAX_LAG_S + FLOOR_CAP_S) * 1000, out
    assert re.search(r"microphone: blocks=\d+", out), out  # the --stats lines carry the group
