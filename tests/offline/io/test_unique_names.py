"""The glTF reader's unique names: the same names as the plain loop (first free of base, base#2, base#3, ...),
in linear time for a file that repeats one name many times."""

from __future__ import annotations

import random

from facepuppet.offline.io.gltf.names import UniqueNames


def _reference(bases: list[str]) -> list[str]:
    used: set[str] = set()
    out = []
    for base in bases:
        name, k = base, 1
        while name in used:
            k += 1
            name = f"{base}#{k}"
        used.add(name)
        out.append(name)
    return out


def test_unique_names_are_the_plain_loops_names():
    rng = random.Random(7)
    for _ in range(500):  # literal names that look like made ones ("a#2") included
        bases = [rng.choice(["a", "b", "a#2", "a#3", "b#2", "", "a#2#2"]) for _ in range(rng.randint(0, 40))]
        unique = UniqueNames()
        assert [unique.take(b) for b in bases] == _reference(bases), bases


def test_a_name_repeated_thirty_thousand_times_counts_on_from_where_it_was():
    unique = UniqueNames()
    names = [unique.take("Bone") for _ in range(30001)]
    assert names[0] == "Bone" and names[1] == "Bone#2" and names[-1] == "Bone#30001"
    assert unique._next["Bone"] == 30001  # one step per take: the loop of the reference would take 30,000 steps


def test_names_taken_beforehand_are_avoided_as_the_plain_loop_avoids_them():
    unique = UniqueNames(["Head", "Body#2"])  # the export's joint names: a mesh host may not take them
    assert [unique.take(n) for n in ("Head", "Body", "Body", "Face")] == ["Head#2", "Body", "Body#3", "Face"]
