"""facepuppet.runtime.session: the one assembler of every session that plays a character.

A command parses its options into frozen groups (:mod:`.options`, :mod:`.input_options`), chooses a feed (the
live trackers of ``run``, :mod:`.live_feed`; a recording, :mod:`.recording_feed`; a list of frames,
:mod:`.feeds`) and opens the session (:mod:`.assemble`), which builds the stage chain, the renderer, the
outputs (:mod:`.outputs`), the panel and the frame loop inside one ``ExitStack``.
"""
