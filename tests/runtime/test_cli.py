"""The command and benchmark registries: every listed module must exist; none is dropped silently."""

from __future__ import annotations

import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.bench import registry as bench_registry


def test_every_listed_command_module_registers():
    parser = cli.build_parser()
    choices = parser._subparsers._group_actions[0].choices  # argparse keeps the subcommands here
    for name in ("run", "replay", "demo", "manipulate", "contact-sheet", "bench", "import-rig", "fit-retarget"):
        assert name in choices


def test_a_missing_command_module_is_an_error_not_a_dropped_command(monkeypatch):
    monkeypatch.setattr(cli, "_COMMAND_MODULES", cli._COMMAND_MODULES + ("facepuppet.runtime.no_such_command",))
    with pytest.raises(ModuleNotFoundError, match="no_such_command"):
        cli.build_parser()


def test_a_missing_bench_module_is_an_error(monkeypatch):
    monkeypatch.setattr(bench_registry, "_BENCH_MODULES", ("facepuppet.runtime.no_such_bench",))
    monkeypatch.setattr(bench_registry, "_LOADED", False)
    monkeypatch.setattr(bench_registry, "_REGISTRY", {})
    with pytest.raises(ModuleNotFoundError, match="no_such_bench"):
        bench_registry.benches()
