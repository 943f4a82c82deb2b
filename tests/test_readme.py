"""The README states what a newcomer must type: every required option of every command and benchmark."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from facepuppet.runtime import cli
from facepuppet.runtime.bench.registry import benches

README = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
FENCED = re.findall(r"```\w*\n(.*?)```", README, re.S)
CODE = re.findall(r"`([^`\n]+)`", re.sub(r"```\w*\n.*?```", "", README, flags=re.S)) + [
    line for block in FENCED for line in block.splitlines()]


def _required(parser: argparse.ArgumentParser) -> list[tuple[str, ...]]:
    return [tuple(a.option_strings) for a in parser._actions if a.required and a.option_strings]


def _mentions(command: str) -> list[str]:
    return [c for c in CODE if re.search(rf"(^|\s|facepuppet ){re.escape(command)}(\s|$)", c)]


def test_every_command_and_its_required_options_are_in_the_readme():
    sub = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    missing = []
    for name, parser in sub.choices.items():
        lines = _mentions(name)
        if not lines:
            missing.append(f"{name}: not in the README")
            continue
        for flags in _required(parser):
            if not any(re.search(rf"(^|\s){re.escape(f)}(\s|$)", line) for line in lines for f in flags):
                missing.append(f"{name}: required {'/'.join(flags)} not shown")
    assert not missing, missing


def test_every_benchmark_with_required_options_shows_them():
    missing = []
    for name, bench in benches().items():
        parser = argparse.ArgumentParser()
        if bench.add_arguments:
            bench.add_arguments(parser)
        lines = _mentions(f"bench {name}")
        for flags in _required(parser):
            if not any(re.search(rf"(^|\s){re.escape(f)}(\s|$)", line) for line in lines for f in flags):
                missing.append(f"bench {name}: required {'/'.join(flags)} not shown")
    assert not missing, missing


def test_the_manipulate_script_format_is_documented():
    assert "manipulate --script steps.json" in README
    for step in ('{"pin": ', '{"unpin": ', '{"reset": true}', '"drag": ', '"by": ', '"to": ', '"pixels": '):
        assert step in README, step
