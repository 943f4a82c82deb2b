"""The commands reference lists every command, benchmark and option, the same on every terminal."""

from __future__ import annotations

import argparse

from facepuppet.runtime import cli
from facepuppet.runtime.bench.registry import bench_parser, benches
from facepuppet.runtime.cli import reference as cli_reference


def _every_parser() -> list[argparse.ArgumentParser]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return [parser, *sub.choices.values(), *(bench_parser(b) for b in benches().values())]


def test_every_command_benchmark_and_option_is_listed():
    page = cli_reference.reference()
    missing = []
    for parser in _every_parser():
        if f"# {parser.prog}\n" not in page:
            missing.append(parser.prog)
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction) or action.help is argparse.SUPPRESS:
                continue
            for flag in action.option_strings:
                if f"`{flag}" not in page and f", {flag}" not in page:
                    missing.append(f"{parser.prog} {flag}")
    assert not missing, missing


def test_the_page_does_not_depend_on_the_terminal(monkeypatch):
    monkeypatch.setenv("COLUMNS", "40")
    narrow = cli_reference.reference()
    monkeypatch.setenv("COLUMNS", "300")
    assert cli_reference.reference() == narrow


def test_a_section_spells_options_as_usage_does_and_fills_in_help_fields():
    parser = argparse.ArgumentParser(prog="facepuppet toy", description="A toy\n   command.")
    parser.add_argument("source", help="what to read")
    parser.add_argument("extra", nargs="*", help="more of them")
    parser.add_argument("-o", "--output", required=True, metavar="OUT.npz", help="where (%(metavar)s)")
    parser.add_argument("--mode", choices=["a", "b"], default="a", help="one of %(choices)s, default %(default)s")
    parser.add_argument("--ratio", type=float, help="25 %% of it; a*b <c> | d, but `x*y` stays")
    parser.add_argument("--fast", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--hidden", help=argparse.SUPPRESS)
    group = parser.add_argument_group("picture", "how it looks")
    group.add_argument("--msaa", type=int, metavar="N", help="samples")
    text = "\n".join(cli_reference.section(parser, "a toy command"))
    assert text.splitlines()[:5] == ["## facepuppet toy", "", "a toy command", "", "A toy command."]
    assert "facepuppet toy --output OUT.npz [options] source [extra ...]" in text
    assert "- `source`: what to read" in text
    assert "- `[extra ...]`: more of them" in text
    assert "- `-o, --output OUT.npz` (required): where (OUT.npz)" in text
    assert "- `--mode {a,b}`: one of a, b, default a" in text
    assert r"- `--ratio RATIO`: 25 % of it; a\*b \<c\> \| d, but `x*y` stays" in text
    assert "- `--fast, --no-fast`" in text
    assert "--hidden" not in text and "--help" not in text
    assert "**picture**: how it looks\n\n- `--msaa N`: samples" in text


def test_main_writes_the_page(tmp_path, capsys):
    target = tmp_path / "commands.md"
    assert cli_reference.main([str(target)]) == 0
    assert target.read_text(encoding="utf-8") == cli_reference.reference()
    assert cli_reference.main([]) == 0
    assert capsys.readouterr().out.endswith(cli_reference.reference())
