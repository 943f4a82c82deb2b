"""Actor tables (eq 2): cubic evaluation, save/load round trip, validation."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.actuation.actor import Actor
from facepuppet.runtime.files.tables import TablesError

from helpers.small_actors import K, make_actor


def test_evaluate_is_eq2_and_tables_round_trip(tmp_path):
    actor = make_actor()
    s = np.array([0.5, -0.2, 1.0, 0.0])
    ref = actor.neutral.astype(np.float64).copy()
    for k in range(K):                                # the obvious loop over eq 2
        a, b, c = (actor.cubic[i, k].astype(np.float64) for i in range(3))
        ref += a * s[k] ** 3 + b * s[k] ** 2 + c * s[k]
    np.testing.assert_allclose(actor.evaluate(s), ref, atol=1e-5)
    back = Actor.load(actor.save(tmp_path / "actor.npz"))
    np.testing.assert_array_equal(back.cubic, actor.cubic)
    assert back.names == actor.names and back.units == "cm"


def test_actor_validation():
    actor = make_actor()
    with pytest.raises(TablesError, match="bounds must contain s = 0"):
        Actor(names=actor.names, units="cm", neutral=actor.neutral, cubic=actor.cubic, unmixing=actor.unmixing,
              class_axes=actor.class_axes, class_marker=actor.class_marker, head_markers=actor.head_markers,
              s_lower=np.full(K, 0.1), s_upper=np.full(K, 1.0))
    with pytest.raises(TablesError, match="cubic"):
        Actor(names=actor.names[:-1], units="cm", neutral=actor.neutral[:-1], cubic=actor.cubic,
              unmixing=actor.unmixing, class_axes=actor.class_axes, class_marker=actor.class_marker,
              head_markers=actor.head_markers, s_lower=actor.s_lower, s_upper=actor.s_upper)
