"""Gesture layer: exact reproduction, determinism, voice-only jaw, the layer over tracked frames."""

import math

import numpy as np
import pytest

from facepuppet.runtime.files.tables import save_tables
from facepuppet.runtime.frames import Frame
from facepuppet.runtime.gestures.candidates import intensity_bin
from facepuppet.runtime.gestures.layer import GestureLayer
from facepuppet.runtime.gestures.synth import RECENT_PENALTY, GestureSynth
from facepuppet.runtime.gestures.tables import load_gesture_db

from helpers.gesture_dbs import small_db


def test_reproduces_reference_with_sigma_zero_and_one_candidate(db):
    synth = GestureSynth(db, seed=0, sigma=0.0, n_candidates=1)
    start = 40
    synth.reset(start=start)
    ref = np.asarray(db["features"])
    jaw = synth.out_names.index("jawOpen")
    for i in range(start + 1, 290):
        out = synth.step_normalised(float(db["intensity"][i]))
        assert synth.picks == {g: i for g in synth.groups}
        assert out[jaw] == ref[i, 0]


def test_same_seed_same_tracks_other_seed_differs(db):
    level = -30 + 12 * np.sin(np.arange(200) / 4.0)
    runs = []
    for seed in (5, 5, 6):
        synth = GestureSynth(db, seed=seed, sigma=0.5, n_candidates=4)
        runs.append(np.array([synth.step(float(v)).copy() for v in level]))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], runs[2])


def test_voice_only_opens_jaw_when_loud_and_closes_it_in_silence(db):
    synth = GestureSynth(db, seed=1)
    layer = GestureLayer(synth, fps=30.0, mode="voice", level=lambda t: -15.0 if 1.0 <= t < 2.0 else math.nan)
    jaw = {}
    for k in range(90):
        f = layer(None, k / 30.0)
        jaw[k] = float(f.weights[f.channels.index("jawOpen")])
    loud = np.mean([jaw[k] for k in range(45, 60)])
    silent = np.mean([jaw[k] for k in range(75, 90)])
    assert loud > 0.6 and silent < 0.05, (loud, silent)


def test_layer_adds_residuals_and_fills_lost_channels(db):
    synth = GestureSynth(db, seed=2)
    layer = GestureLayer(synth, fps=30.0, mode="add")
    tracked = Frame(0.0, source="llf", channels=("BrowInnerUp", "JawOpen"), weights=[0.5, np.nan],
                    audio_level=-20.0)
    out = layer(tracked, 0.0)
    add = dict(zip(synth.out_names, synth.additions - synth.mood_part))
    assert out.channels[:2] == ("BrowInnerUp", "JawOpen")
    assert out.weights[0] == pytest.approx(0.5 + add["browInnerUp"], abs=1e-6)
    assert out.weights[1] == pytest.approx(synth.additions[synth.out_names.index("jawOpen")], abs=1e-6)
    assert "eyeBlinkLeft" in out.channels and out.head_rotation is not None


def test_style_restricts_a_group_to_one_take(db):
    synth = GestureSynth(db, seed=3, style={"brows": "take1"}, sigma=0.5, n_candidates=4)
    for v in -30 + 10 * np.sin(np.arange(150) / 3.0):
        synth.step(float(v))
        assert db["frame_take"][synth.picks["brows"]] == 1
    with pytest.raises(ValueError, match="style"):
        GestureSynth(db, style={"brows": "nope"})


def slow_distance(synth, k, i, speech, history, mood_prev):
    """§5.1 distance of reference frame i for group k, by loops over the h preceding frames."""
    h, a = synth.h, synth._alpha[k]
    d = sum(a / h * (speech[-1 - lag] - synth._intensity[i - lag]) ** 2 for lag in range(h))
    d += sum((1 - a) / h * np.sum((history[-lag] - synth._desc[i - lag, k]) ** 2) for lag in range(1, h + 1))
    if synth._km >= 0:
        d += synth._beta[k] * np.sum((mood_prev - synth._moodf[i - 1]) ** 2)
    return d


def test_step_distance_matches_the_slow_definition_and_the_successor_has_no_continuity_cost(db):
    synth = GestureSynth(db, seed=4, sigma=0.0, n_candidates=1)
    rng = np.random.default_rng(0)
    speech = list(synth._intensity[synth._pick[0] + np.arange(-synth.h + 1, 1)])  # reset's speech history
    hist = {k: [synth._desc[synth._pick[k] + lag, k] for lag in range(-synth.h + 1, 1)]
            for k in range(len(synth.groups))}
    shown = {k: {int(synth._pick[k]): 0} for k in range(len(synth.groups))}  # frame -> step it was last shown
    for t, a in enumerate(rng.normal(0, 1.5, 40), 1):
        prev = synth._pick.copy()
        mood_prev = synth._moodf[prev[synth._km]]
        speech.append(a)
        b = intensity_bin(a)
        synth.step_normalised(float(a))
        for k in range(len(synth.groups)):
            cand = [c for c in list(synth._T_raw[k, prev[k]]) + list(synth._T_raw[k, len(synth._intensity) + b])
                    if c < len(synth._intensity)]
            d = [slow_distance(synth, k, c, speech, hist[k], mood_prev) for c in cand]
            if cand[0] == prev[k] + 1:  # the natural successor continues perfectly: speech (+ mood) term only
                d[0] = slow_distance(synth, k, cand[0], speech, [synth._desc[cand[0] - lag, k] for lag in
                                                                 range(synth.h, 0, -1)], mood_prev)
            if synth.groups[k] != "lips":  # a frame shown in the last `recent` steps is barred (not the lips)
                d = [v + RECENT_PENALTY * (shown[k].get(c, -10 ** 9) >= t - synth.recent) for v, c in zip(d, cand)]
            best = int(np.argmin(d))
            assert synth._pick[k] == cand[best] or d[cand.index(synth._pick[k])] <= d[best] + 1e-4  # float32
            hist[k].append(synth._desc[synth._pick[k], k])
            shown[k][int(synth._pick[k])] = t


def test_picks_run_through_consecutive_reference_frames(db):
    # the MRF's own preference for continuity, without the bar on recent frames (which, on this 600-frame
    # database, bars a quarter of it at the default 150 and so forces jumps; the real database's runs are
    # measured by the bench: run_length_frames)
    synth = GestureSynth(db, seed=0, recent=0)
    for v in -30 + 12 * np.sin(np.arange(600) / 9.0):
        synth.step(float(v))
    runs = synth.run_lengths
    # the continuity-led groups jump rarely; the lips (α = 0.9) follow the noisy synthetic speech instead
    assert min(runs[g] for g in ("brows", "eyes", "rest", "head")) > 3.0, runs


def test_bad_settings_and_bad_start_are_refused(db):
    with pytest.raises(ValueError, match="sigma >= 0"):
        GestureSynth(db, sigma=-1.0)
    with pytest.raises(ValueError, match="variance"):
        GestureSynth(db, variance=0.0)
    synth = GestureSynth(db)
    with pytest.raises(ValueError, match="not a valid start"):
        synth.reset(start=0)
    assert np.isfinite(synth.step(math.nan)).all()  # NaN level: silence, not an error


def test_detail_weights_follow_the_head_pick_as_extra_channels(db):
    n = len(db["intensity"])
    table = np.column_stack([np.arange(n), -np.arange(n)]).astype(np.float32)  # frame index, recognisable
    layer = GestureLayer(GestureSynth(db, seed=3), fps=30.0, mode="voice", level=lambda t: -20.0,
                         detail=(("detail_brows_0", "detail_lips_0"), table))
    for k in range(20):
        f = layer(None, k / 30.0)
        head = layer.synth.picks["head"]
        assert f.channels[-2:] == ("detail_brows_0", "detail_lips_0")
        assert list(f.weights[-2:]) == [head, -head]
    with pytest.raises(ValueError, match="detail: expected a head group and a table of shape"):
        GestureLayer(GestureSynth(db), fps=30.0, detail=(("a",), table))


def test_recent_frames_are_barred_so_a_still_stretch_does_not_loop(tmp_path):
    """A still stretch matches itself h frames back: without the bar the picks cycle through it."""
    db = small_db(tmp_path / "still.npz", n_takes=2, n=400, seed=3)
    arrays = {k: np.array(db[k]) for k in db.arrays}
    arrays["features"][:, 1:] = 0.0                      # gestures and mood still everywhere ...
    arrays["features"][::37, 1:] = 1.0                   # ... but for an event every 37 frames
    arrays["intensity"][:] = 0.0
    save_tables(tmp_path / "still.npz", "gesture_db", arrays, channels=dict(db.channels), settings={"fps": 30.0})
    db = load_gesture_db(tmp_path / "still.npz")
    for recent, loops in ((0, True), (100, False)):
        synth = GestureSynth(db, seed=1, sigma=0.0, n_candidates=1, recent=recent)
        last, min_gap = {}, np.inf
        for t in range(1, 1500):
            synth.step_normalised(0.0)
            p = int(synth._pick[synth.groups.index("eyes")])
            min_gap = min(min_gap, t - last.get(p, -np.inf))
            last[p] = t
        assert (min_gap <= 36) == loops, (recent, min_gap)
        if not loops:
            assert min_gap > 100
    with pytest.raises(ValueError, match="recent >= 0"):
        GestureSynth(db, recent=-1)


def test_eyes_show_one_reference_frame_whole_not_the_mood_picks_lid(db):
    """A blink is drawn from one reference moment: eyeBlinkLeft is the eyes pick's own value (residual + the
    same frame's c·B), never the eyes residual plus the c·B of the mood group's (different) pick."""
    F, B = np.asarray(db["features"], np.float64), np.asarray(db["blend_basis"], np.float64)
    names = list(db.channels["features"])
    blink, mood = names.index("eyeBlinkLeft"), [names.index("mood_0"), names.index("mood_1")]
    assert np.abs(B[:, blink]).max() > 0  # the mood basis does move the lid
    runs = []
    for whole in (("eyes",), ()):
        synth = GestureSynth(db, seed=4, sigma=0.5, n_candidates=4, whole=whole)
        j = synth.out_names.index("eyeBlinkLeft")
        out, picks = [], []
        for v in -30 + 12 * np.sin(np.arange(200) / 4.0):
            out.append(float(synth.step(float(v))[j]))
            picks.append((synth.picks["eyes"], synth.picks["mood"]))
            # add mode adds the eyes residual of the eyes pick (the mood part is the eyes pick's own)
            assert synth.additions[j] - synth.mood_part[j] == pytest.approx(F[picks[-1][0], blink], abs=1e-5)
        pe, pm = np.array(picks).T
        runs.append((np.array(out), pe, pm))
    out, pe, pm = runs[0]
    assert np.mean(pe != pm) > 0.5  # the two groups pick different frames, so the sum would mix two moments
    np.testing.assert_allclose(out, F[pe, blink] + F[pe][:, mood] @ B[:, blink], atol=1e-5)
    out, pe, pm = runs[1]  # whole=(): the paper's plain sum, the lid of two moments
    np.testing.assert_allclose(out, F[pe, blink] + F[pm][:, mood] @ B[:, blink], atol=1e-5)
    assert np.abs(F[pm][:, mood] @ B[:, blink] - F[pe][:, mood] @ B[:, blink]).max() > 0.05
    with pytest.raises(ValueError, match="whole"):
        GestureSynth(db, whole=("lips",))
