"""The progress line: drawn only on a terminal, rate and estimate from the clock."""

import io

from facepuppet.runtime.cli.progress import Progress


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_estimate_follows_the_rate_and_the_line_ends_on_close():
    clock, out = Clock(), Tty()
    with Progress("fit", 100, unit="folds", stream=out, clock=clock, interval_s=0) as p:
        clock.t += 10
        p.update(25, "k=4")
        assert p.line() == "fit: 25/100 folds (25%), 2.5/s, ~30 s left"
        clock.t += 30
        p.update(100)
    text = out.getvalue()
    assert "\rfit: 25/100 folds (25%), 2.5/s, ~30 s left  k=4" in text
    assert text.endswith("fit: 100/100 folds (100%), 2.5/s, 40 s\n")


def test_quiet_when_not_a_terminal():
    out = io.StringIO()  # isatty() is False
    p = Progress("replay", 10, stream=out)
    for _ in range(10):
        p.advance()
    p.close("done")
    assert out.getvalue() == ""
    assert p.done == 10


def test_redraws_at_most_every_interval():
    clock, out = Clock(), Tty()
    p = Progress("import", 1000, stream=out, clock=clock, interval_s=1.0)
    for i in range(1000):
        clock.t += 0.01  # 10 s in all
        p.update(i + 1)
    p.close()
    assert 9 <= out.getvalue().count("\r") <= 12


def test_unknown_total_and_long_estimates():
    clock, out = Clock(), Tty()
    p = Progress("soak", None, unit="frames", stream=out, clock=clock, interval_s=0)
    clock.t += 2
    p.update(240)
    assert p.line() == "soak: 240 frames, 120/s"
    q = Progress("bench", 10, stream=out, clock=clock)
    clock.t += 4000
    q.update(1)
    assert q.line().endswith("~10 h 00 min left")


def test_write_prints_a_line_above_the_progress_line_terminal_or_not():
    import io

    quiet = io.StringIO()
    p = Progress("job", total=4, stream=quiet, enabled=False)
    p.update(2)
    p.write("head markers: A, B, C")
    assert quiet.getvalue() == "head markers: A, B, C\n"         # a result line even when not a terminal
    shown = io.StringIO()
    t = [0.0]
    p = Progress("job", total=4, stream=shown, enabled=True, clock=lambda: t[0])
    p.update(1)
    p.write("a result")
    lines = shown.getvalue().split("\n")
    assert lines[0].endswith("a result") and lines[0].startswith("\rjob: 1/4")   # cleared, then the text
    assert lines[1].startswith("\rjob: 1/4")                                    # the progress line again


def test_piped_lines_are_plain_and_spaced_by_piped_every_s():
    """Asked for (``piped_every_s``), a log gets a whole line now and then: no carriage return, no redraws."""
    clock, out = Clock(), io.StringIO()
    p = Progress("replay", 100, unit="ticks", stream=out, clock=clock, piped_every_s=30)
    for _ in range(100):
        clock.t += 1
        p.advance()
    p.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    assert lines == ["replay: 30/100 ticks (30%), 1/s, ~1 min 10 s left",
                     "replay: 60/100 ticks (60%), 1/s, ~40 s left",
                     "replay: 90/100 ticks (90%), 1/s, ~10 s left"]


def test_piped_lines_are_off_unless_asked_and_never_on_a_terminal():
    clock = Clock()
    quiet, tty = io.StringIO(), Tty()
    for stream, every in ((quiet, None), (tty, 1.0)):
        p = Progress("x", 10, stream=stream, clock=clock, interval_s=1000, piped_every_s=every)
        for _ in range(10):
            clock.t += 5
            p.advance()
    assert quiet.getvalue() == ""
    assert "\n" not in tty.getvalue()  # the terminal's line is redrawn in place, not logged
