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
