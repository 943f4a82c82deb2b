"""``bench latency``'s map-step figure: the map the frame loop would build for the character and the VMC input."""

from __future__ import annotations

from facepuppet.runtime.bench.latency import map_step_cost

from helpers.small_characters import sphere_character
from helpers.vrm_characters import preset_character


def test_the_map_step_is_timed_on_the_map_the_loop_builds(tmp_path):
    plain = map_step_cost(sphere_character().save(tmp_path / "sphere.npz"), n=50)
    assert plain["map"] == "ChannelMap" and plain["channels"] == 52 and plain["expressions"] == 0
    vrm = map_step_cost(preset_character().save(tmp_path / "avatar.npz"), n=50)
    # the VMC input carries the avatar's 18 expression names after the 52 ARKit channels
    assert vrm["map"] == "ExpressionMap" and vrm["channels"] == 52 + 18 and vrm["shapes"] == 14
    assert vrm["n"] == 50 and 0 < vrm["p50_us"] <= vrm["p99_us"] <= vrm["max_us"]
