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


@pytest.mark.parametrize("command", [["contact-sheet", "{c}", "-o", "{tmp}/sheet.png"],
                                     ["bench", "render", "-c", "{c}", "--frames", "2", "--json", "{tmp}/b.json"]])
def test_rendering_commands_without_egl_exit_3_with_one_line(tmp_path, command):
    """With the EGL vendor libraries hidden (glvnd finds no driver), the command says so and exits 3.

    A child process, so the test's own process keeps its GL; it never gets a context to render with.
    """
    import os
    import subprocess
    import sys
    from pathlib import Path

    character = Path(__file__).parent / "data" / "tables_v1" / "character.npz"
    argv = [a.format(c=character, tmp=tmp_path) for a in command]
    env = dict(os.environ, __EGL_VENDOR_LIBRARY_FILENAMES=str(tmp_path / "none.json"), DISPLAY="")
    done = subprocess.run([sys.executable, "-m", "facepuppet", *argv], capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr and "no headless EGL OpenGL 3.3 context" in done.stderr
