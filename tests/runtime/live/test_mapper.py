"""The map step shared by the frame loop and the panel: one cache, the loop's report logged once per layout
even when the panel asked for the layout first, and bounded."""

from __future__ import annotations

from facepuppet.runtime.live.mapper import MAX_CHANNEL_MAPS, Mapper

NAMES = ("jawOpen", "browInnerUp_L", "browInnerUp_R")


def test_the_panel_asking_first_neither_logs_nor_keeps_the_loop_from_reporting():
    lines: list[str] = []
    mapper = Mapper(NAMES, log=lines.append)
    layout = ("browInnerUp", "jawOpen")
    assert list(mapper.first_targets(layout)[0]) == [1, 0]  # the panel's meters: no report from them
    assert lines == []
    first = mapper.map_for(layout, "vmc")                    # the loop's first frame of that layout
    assert len(lines) == 1 and lines[0].startswith("channel map (vmc): 2 source channels -> 3 of 3")
    assert mapper.map_for(layout, "vmc") is first and len(lines) == 1  # once per layout
    assert mapper.map_for(layout, report=False) is first     # and the panel reads the loop's map


def test_every_cache_is_bounded_and_an_evicted_layout_is_reported_again():
    lines: list[str] = []
    mapper = Mapper(NAMES, log=lines.append)
    layouts = [(f"c{i}",) for i in range(MAX_CHANNEL_MAPS + 5)]
    for layout in layouts:
        mapper.first_targets(layout)
        mapper.map_for(layout)
    assert max(len(mapper._maps), len(mapper._quiet), len(mapper._first)) <= MAX_CHANNEL_MAPS
    assert len(lines) == len(layouts)
    mapper.map_for(layouts[0])  # evicted: built and reported again
    assert len(lines) == len(layouts) + 1
