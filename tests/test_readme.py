"""The README stays a five-minute read and the docs stay true to the code.

The README is short and fixed in shape (the quick start, a table with every command); the reference
lives in docs/, and docs/commands.md is written from the parser itself. Every ``facepuppet ...`` line the
README or a docs page shows parses with the real parser, so an example cannot name an option that is
gone or leave out one that is required; every command and benchmark has such an example; every relative
link leads somewhere.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.bench.registry import bench_parser, benches
from facepuppet.runtime.cli import reference as cli_reference

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
COMMANDS_MD = DOCS / "commands.md"
# the pages people write; docs/commands.md is generated and checked against its generator instead
WRITTEN = [README, *sorted(p for p in DOCS.glob("*.md") if p != COMMANDS_MD)]
EVERY_PAGE = [*WRITTEN, COMMANDS_MD]

# a fenced block, also one indented under a list item
FENCE = re.compile(r"^[ \t]*```[^\n]*\n(.*?)^[ \t]*```", re.S | re.M)
# inline code; a span broken over two lines is read as one, as Markdown renders it
INLINE = re.compile(r"`([^`]+)`")


def _text(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _command_lines(path: Path) -> list[str]:
    """Each ``facepuppet ...`` a page shows: the lines of its code blocks and its inline code."""
    text = _text(path)
    found = []
    for block in FENCE.findall(text):
        for line in block.replace("\\\n", " ").splitlines():
            if line.strip().startswith("facepuppet "):
                found.append(line.strip())
    for span in INLINE.findall(FENCE.sub("", text)):
        span = " ".join(span.split())
        if span.startswith("facepuppet "):
            found.append(span)
    return found


def _parse(line: str) -> tuple[list[str], str | None]:
    """The words of ``line`` after ``facepuppet`` and what argparse says against them (None: it parses).

    A bare ``facepuppet NAME`` (or ``facepuppet bench NAME``) names a command in prose and only has to
    name one that exists; anything longer is a command line and has to parse, a benchmark's options with
    that benchmark's own parser.
    """
    words = shlex.split(line, comments=True)[1:]
    if not words:
        return words, "no command"
    commands = _commands()
    if words[0] not in commands:
        return words, f"no command {words[0]!r}"
    if words[0] == "bench" and len(words) > 1 and words[1] not in benches():
        return words, f"no benchmark {words[1]!r}"
    if len(words) == 1 or (words[0] == "bench" and len(words) == 2):
        return words, None
    stderr = io.StringIO()
    try:
        with contextlib.redirect_stderr(stderr):
            args = cli.build_parser().parse_args(words)
            if args.command == "bench" and args.name:
                bench_parser(benches()[args.name]).parse_args(args.options)
    except SystemExit:
        return words, stderr.getvalue().strip().splitlines()[-1]
    return words, None


def test_the_readme_is_a_five_minute_read():
    lines = _text(README).splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines; the reference belongs in docs/"


def test_the_quick_start_is_make_demo_and_make_test():
    section = _text(README).split("## Quick start", 1)[1]
    first_block = FENCE.search(section).group(1)
    assert first_block.split("\n") == ["make demo", "make test", ""]


def test_every_command_is_in_the_readme_table():
    rows = re.findall(r"^\| `([a-z-]+)` \|", _text(README).split("## Commands", 1)[1], re.M)
    assert sorted(rows) == sorted(_commands()), "README's command table and the parser's commands differ"


@pytest.mark.parametrize("page", WRITTEN, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_command_line_shown_parses(page):
    wrong = []
    for line in _command_lines(page):
        _, error = _parse(line)
        if error:
            wrong.append(f"{line}\n    -> {error}")
    assert not wrong, "\n".join(wrong)


def test_every_command_and_benchmark_has_a_worked_example():
    """Each command, and each benchmark, appears as a full command line somewhere a user reads; since
    those lines parse, each shows its command's required options."""
    shown: set[str] = set()
    for page in WRITTEN:
        for line in _command_lines(page):
            words, error = _parse(line)
            if error is None and len(words) > 1:
                shown.add(words[0])
                if words[0] == "bench" and len(words) > 2:
                    shown.add(f"bench {words[1]}")
    wanted = set(_commands()) | {f"bench {name}" for name in benches()}
    assert not wanted - shown, f"no example of: {sorted(wanted - shown)}"


def _slug(heading: str) -> str:
    return cli_reference.anchor(heading)


def _anchors(path: Path) -> set[str]:
    return {_slug(h) for h in re.findall(r"^#+ (.+)$", FENCE.sub("", _text(path)), re.M)}


@pytest.mark.parametrize("page", [*EVERY_PAGE, ROOT / "ARCHITECTURE.md"], ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_relative_link_leads_somewhere(page):
    text = INLINE.sub("", FENCE.sub("", _text(page)))
    broken = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z]+:", target):
            continue   # http:, https:, mailto:
        file, _, anchor = target.partition("#")
        dest = (page.parent / file).resolve() if file else page
        if not dest.exists():
            broken.append(f"{target}: no {dest.relative_to(ROOT) if dest.is_relative_to(ROOT) else dest}")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            broken.append(f"{target}: no heading #{anchor} in {dest.name}")
    assert not broken, broken


def test_docs_commands_md_is_what_the_parser_says_now():
    assert COMMANDS_MD.exists(), "docs/commands.md is missing: run `make docs`"
    assert _text(COMMANDS_MD) == cli_reference.reference(), (
        "docs/commands.md is not what the commands' argparse definitions give now: run `make docs` "
        "(python -m facepuppet.runtime.cli.reference docs/commands.md) and commit it")


def test_the_manipulate_script_format_is_documented():
    training = _text(DOCS / "training.md")
    assert "manipulate --script steps.json" in training
    for step in ('{"pin": ', '{"unpin": ', '{"reset": true}', '"drag": ', '"by": ', '"to": ', '"pixels": '):
        assert step in training, step
