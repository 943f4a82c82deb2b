"""The solve's saturation count: what it names must be what the frames did."""

import numpy as np

from facepuppet.runtime.actuation.saturation import SaturationCount


def test_fractions_name_the_channels_and_actuations_at_their_limit():
    count = SaturationCount(("jawOpen", "mouthSmile_L", "eyeBlink_L"), 2, np.array([-1.0, -1.0]),
                            np.array([1.0, 2.0]))
    for i in range(10):
        w = np.array([1.0 if i < 4 else 0.5, 0.999, 0.0])       # jawOpen at 1.0 in 4 of 10 frames
        s = np.array([1.0 if i < 3 else 0.2, -0.5])              # s01 at its upper bound in 3 of 10
        count.add(s, w)
    f = count.fractions()
    assert f == {"frames": 10, "channels_at_1": {"jawOpen": 0.4}, "actuations_at_bound": {"s01": 0.3}}
    line = count.line()
    assert "jawOpen 40%" in line and "s01 30%" in line and "mouthSmile_L" not in line


def test_nothing_at_the_limit_says_none():
    count = SaturationCount(("a",), 1, np.array([-1.0]), np.array([1.0]))
    count.add(np.array([0.1]), np.array([0.2]))
    assert count.fractions()["channels_at_1"] == {}
    assert "channels at 1.0: none" in count.line()
