"""A marker take replayed through its own actor and a pair onto the ICT head starts and ends near the
character's neutral: measured with the real commands, on both kit takes.

Tolerance: at the first and the last tick the character's largest vertex offset from its neutral is at most
1.5 x the largest marker offset of the take from the actor's neutral (head coordinates, scaled by the two
faces' FAPU into the character's units) + 0.1 cm. The takes' first and last frames are not the actor's
neutral themselves (0.2-0.4 cm RMS away), so the character may move, but no more than the actor did: the
jaw take's first frame (lips pressed, 0.89 cm at most on ICT's scale) once came out as an open mouth of
2.65 cm. The actor's own neutral frame gives the character's neutral (under 0.05 cm).

The scale between the faces that the tolerance uses is the pair's own; what retarget-actor prints about it
is checked against the landmark distances computed here.
"""

import json
import subprocess
import sys
from itertools import combinations

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.actuation.pair import ActorPair
from facepuppet.runtime.actuation.solver import MarkerSolver
from facepuppet.runtime.model.character import Character

from conftest import need_shared
from facepuppet.offline.actuation.face_scale import UNCERTAIN_SPREAD
from facepuppet.offline.actuation.transfer import MARKER_LANDMARKS, character_landmarks
from facepuppet.offline.actuation.transfer_eval import head_coordinates
from facepuppet.offline.io.capture import read_capture

pytestmark = [pytest.mark.data, pytest.mark.slow, pytest.mark.gl]
FPS = 10  # ticks per second of the replay: the first tick is frame 0, the last within 0.1 s of the end


def facepuppet(*args: str) -> subprocess.CompletedProcess:
    out = subprocess.run([sys.executable, "-m", "facepuppet", *args], capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return out


def mesh_offset(character: Character, weights: np.ndarray) -> float:
    return float(np.linalg.norm(np.tensordot(weights.astype(np.float64), character.dense_deltas(), 1), axis=1).max())


@pytest.mark.parametrize("take_name", ["animface_cheeks.trc", "animface_jaw.trc"])
def test_replay_of_a_take_through_its_own_actor_starts_and_ends_near_neutral(take_name, ict_character_path,
                                                                             ict_character, tmp_path):
    take = need_shared("markers", take_name)
    actor_path, pair_path, dump = tmp_path / "actor.npz", tmp_path / "pair.npz", tmp_path / "w.npy"
    facepuppet("train-actor", str(take), "-o", str(actor_path))
    retargeted = facepuppet("retarget-actor", str(actor_path), str(ict_character_path), "-o", str(pair_path))
    out = facepuppet("replay", str(take), "-c", str(ict_character_path), "--actor", str(actor_path), "--pair",
                     str(pair_path), "--headless", "--size", "64x48", "--fps", str(FPS), "--dump-weights",
                     str(dump), "--stats")
    actor, pair = Actor.load(actor_path), ActorPair.load(pair_path)
    weights = np.load(dump)
    capture = read_capture(take)
    frames = head_coordinates(actor, capture.markers[:, [capture.names.index(n) for n in actor.names]])
    m = pair.metadata["metrics"]
    scale = m["fapu_character"] / m["fapu_actor"]
    ticks = {"first": (0, 0), "last": (len(weights) - 1, min(round((len(weights) - 1) * capture.rate / FPS),
                                                             len(frames) - 1))}
    for label, (tick, frame) in ticks.items():
        actor_offset = float(np.linalg.norm(frames[frame] - actor.neutral, axis=1).max()) * scale
        character_offset = mesh_offset(ict_character, weights[tick])
        assert character_offset <= 1.5 * actor_offset + 0.1, (
            f"{take_name} {label} tick: the character moves {character_offset:.2f} cm where the actor's markers "
            f"moved {actor_offset:.2f} cm (ICT's scale)")
    # the actor's own neutral is the character's neutral
    rest = MarkerSolver(actor).solve(actor.neutral)
    assert mesh_offset(ict_character, pair.weights(rest)) < 0.05
    # the face-size ratio is the median of the landmark-marker distance ratios, computed here on its own, and
    # the command calls it uncertain exactly when their middle half is wider than UNCERTAIN_SPREAD of it
    landmarks = character_landmarks(ict_character)
    on = [name for name in MARKER_LANDMARKS if name in actor.names]
    a = actor.neutral[[actor.names.index(n) for n in on]].astype(np.float64)
    c = ict_character.vertices[landmarks[[MARKER_LANDMARKS[n] for n in on]]].astype(np.float64)
    ratios = [np.linalg.norm(c[i] - c[j]) / np.linalg.norm(a[i] - a[j]) for i, j in combinations(range(len(on)), 2)]
    low, median, high = np.quantile(ratios, [0.25, 0.5, 0.75])
    assert scale == pytest.approx(median, rel=1e-4)
    assert f"face-size ratio {median:.3f} (median of {len(ratios)} landmark-distance ratios" in retargeted.stdout
    assert ("the scale is uncertain" in retargeted.stdout) == ((high - low) / median > UNCERTAIN_SPREAD)
    # saturation is counted by name in --stats
    summary = json.loads(next(line for line in out.stdout.splitlines() if line.startswith("{")))
    saturation = summary["saturation"]
    assert saturation["frames"] == summary["n_ticks"] - summary["counters"]["ticks_without_new_frame"]
    assert set(saturation["channels_at_1"]) <= set(pair.shape_names)
    assert "solve saturation over" in out.stdout
