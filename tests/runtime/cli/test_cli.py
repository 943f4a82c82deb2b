"""The command line: the command and benchmark registries (every listed module must exist; none is dropped
silently), and what ``cli.main`` makes of an exception (a refusal: one line and exit 2; a bug: its traceback)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

import facepuppet.runtime
from facepuppet.runtime.bench import registry as bench_registry
from facepuppet.runtime.cli import command as cli
from facepuppet.runtime.errors import FacepuppetError, InputFileError, UsageError
from facepuppet.runtime.inputs.counted import Dropped, counted
from facepuppet.runtime.inputs.ifacialmocap import IFacialMocapAdapter
from facepuppet.runtime.inputs.udp_channel import ChannelError
from facepuppet.runtime.inputs.udp_process import UdpProcessSource
from facepuppet.runtime.inputs.vmc import VmcAdapter
from facepuppet.runtime.inputs.vtubestudio import VTubeStudioAdapter
from facepuppet.runtime.render.gl_context import GLUnavailable

import facepuppet.offline
from facepuppet.offline.io.gltf_check import check_gltf_bytes


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

    character = Path(__file__).resolve().parents[1] / "files" / "data" / "tables_v1" / "character.npz"
    argv = [a.format(c=character, tmp=tmp_path) for a in command]
    env = dict(os.environ, __EGL_VENDOR_LIBRARY_FILENAMES=str(tmp_path / "none.json"), DISPLAY="")
    done = subprocess.run([sys.executable, "-m", "facepuppet", *argv], capture_output=True, text=True, env=env,
                          timeout=300)
    assert done.returncode == 3, done.stderr
    assert "Traceback" not in done.stderr and "no headless EGL OpenGL 3.3 context" in done.stderr


# -- refusals and bugs --------------------------------------------------------------------------------------

CHARACTER = Path(__file__).resolve().parents[1] / "files" / "data" / "tables_v1" / "character.npz"


def _with_func(monkeypatch, command: str, func) -> None:
    """``cli.main`` builds a parser whose ``command`` runs ``func``."""
    parser = cli.build_parser()
    parser._subparsers._group_actions[0].choices[command].set_defaults(func=func)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)


def test_a_refusal_exits_2_with_one_line_and_no_traceback(capsys, monkeypatch):
    monkeypatch.delenv("FACEPUPPET_DEBUG", raising=False)
    assert cli.main(["bench", "soak", "-c", str(CHARACTER), "--seconds", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == ["facepuppet bench: error: bench soak: a length must be a finite number >= 0, "
                                "got -1.0"]


@pytest.mark.parametrize("refusal", [UsageError("--x: expected y"), InputFileError("a.toml: key 'z': no"),
                                     FileNotFoundError(2, "No such file or directory", "a.npz")])
def test_every_refusal_is_one_line_and_exit_2(capsys, monkeypatch, tmp_path, refusal):
    monkeypatch.delenv("FACEPUPPET_DEBUG", raising=False)

    def refuse(args):
        raise refusal

    _with_func(monkeypatch, "import-rig", refuse)
    assert cli.main(["import-rig", str(tmp_path / "a.obj"), "-o", str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err
    assert err == f"facepuppet import-rig: error: {refusal}\n"


@pytest.mark.parametrize("bug", [ValueError("operands could not be broadcast together"), ZeroDivisionError("x"),
                                 KeyError("n_shapes"), TypeError("unhashable type: 'list'")])
def test_a_bug_is_not_a_refusal_its_traceback_shows(capsys, monkeypatch, tmp_path, bug):
    """A plain ValueError (or any exception that is not a FacepuppetError or an OSError) is a bug in facepuppet:
    cli.main lets it through, so Python prints its traceback and exits 1."""
    def broken(args):
        raise bug

    _with_func(monkeypatch, "import-rig", broken)
    with pytest.raises(type(bug)) as raised:
        cli.main(["import-rig", str(tmp_path / "a.obj"), "-o", str(tmp_path / "a.npz")])
    assert raised.value is bug
    assert "error:" not in capsys.readouterr().err


def test_a_bug_in_the_command_line_shows_a_traceback_and_exits_1(tmp_path):
    """The whole path, as a user meets it: ``python -m facepuppet`` on a bug prints the traceback."""
    script = ("import sys\n"
              "from facepuppet.runtime.cli import command as cli\n"
              "parser = cli.build_parser()\n"
              "def broken(args):\n"
              "    return 1 / 0\n"
              "parser._subparsers._group_actions[0].choices['import-rig'].set_defaults(func=broken)\n"
              "cli.build_parser = lambda: parser\n"
              "sys.exit(cli.main(sys.argv[1:]))\n")
    done = subprocess.run([sys.executable, "-c", script, "import-rig", str(tmp_path / "a.obj"), "-o",
                           str(tmp_path / "a.npz")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert "Traceback (most recent call last)" in done.stderr and "ZeroDivisionError" in done.stderr
    assert "error:" not in done.stderr


def test_facepuppet_debug_shows_the_traceback_of_a_refusal_then_its_line(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("FACEPUPPET_DEBUG", "1")

    def refuse(args):
        raise InputFileError(f"{tmp_path / 'a.obj'}: line 3: expected 3 numbers")

    _with_func(monkeypatch, "import-rig", refuse)
    assert cli.main(["import-rig", str(tmp_path / "a.obj"), "-o", str(tmp_path / "a.npz")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("Traceback (most recent call last)") and "in refuse" in err
    assert err.splitlines()[-1] == f"facepuppet import-rig: error: {tmp_path / 'a.obj'}: line 3: expected 3 numbers"


def test_facepuppet_debug_keeps_the_exit_code_of_no_opengl(capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("FACEPUPPET_DEBUG", "1")

    def no_gl(args):
        raise GLUnavailable("no headless EGL OpenGL 3.3 context")

    _with_func(monkeypatch, "import-rig", no_gl)
    assert cli.main(["import-rig", str(tmp_path / "a.obj"), "-o", str(tmp_path / "a.npz")]) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and err.splitlines()[-1] == ("facepuppet import-rig: error: no headless EGL OpenGL "
                                                           "3.3 context")


def test_an_interrupt_exits_130(capsys, monkeypatch, tmp_path):
    def interrupted(args):
        raise KeyboardInterrupt

    _with_func(monkeypatch, "import-rig", interrupted)
    assert cli.main(["import-rig", str(tmp_path / "a.obj"), "-o", str(tmp_path / "a.npz")]) == 130
    assert capsys.readouterr().err == "facepuppet import-rig: interrupted\n"


# -- every error class is the project's --------------------------------------------------------------------

# Exceptions used for control flow inside one module, never let out of it: gltf_check's _Stop ends the checker's
# walk (check_gltf_bytes catches it); inputs.counted's Dropped names the counter of a dropped datagram (counted()
# catches it, and only the adapters' private decoders, run inside counted(), raise it); the process receiver's
# ChannelError, a message on its own socket pair that it cannot read (UdpProcessSource counts it as an
# internal_error and keeps it in last_error).
CONTROL_FLOW = {("facepuppet.offline.io.gltf_check", "_Stop"), ("facepuppet.runtime.inputs.counted", "Dropped"),
                ("facepuppet.runtime.inputs.udp_channel", "ChannelError")}


def _exception_classes():
    found = []
    for package in (facepuppet.runtime, facepuppet.offline):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            if info.name.endswith("__main__"):   # runs the command
                continue
            module = importlib.import_module(info.name)
            found += [(module.__name__, name) for name, obj in vars(module).items()
                      if inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == module.__name__]
    return found


def test_every_exception_class_of_the_project_is_a_facepuppet_error():
    found = _exception_classes()
    assert ("facepuppet.runtime.files.tables_error", "TablesError") in found and len(found) > 15
    assert CONTROL_FLOW <= set(found)
    outside = [f"{module}.{name}" for module, name in found if (module, name) not in CONTROL_FLOW
               and not issubclass(getattr(importlib.import_module(module), name), FacepuppetError)]
    assert not outside, f"not FacepuppetError subclasses: {outside}"


def test_every_refusal_class_but_no_opengl_is_a_value_or_runtime_error_too():
    """So code (and tests) catching the ValueError of a reader or the RuntimeError of a device still does."""
    for module, name in _exception_classes():
        cls = getattr(importlib.import_module(module), name)
        if (module, name) not in CONTROL_FLOW and cls is not FacepuppetError:
            assert issubclass(cls, (ValueError, RuntimeError)), f"{module}.{name}"


def test_the_control_flow_exceptions_do_not_escape():
    assert check_gltf_bytes(b"glTF\x02\x00\x00\x00\x10\x00\x00\x00\xff\xff\xff\xff")   # _Stop: a problem, not raised
    assert check_gltf_bytes(b"{not json")

    def drop(data, t):
        raise Dropped("malformed")

    counters = {"datagrams": 0, "malformed": 0, "frames": 0, "internal_error": 0}
    assert counted(counters, drop, b"x", 0.0) is None and counters["malformed"] == 1
    for adapter in (IFacialMocapAdapter(), VTubeStudioAdapter()):
        for data in (b"", b"\xff", b"{}", b'{"BlendShapes": [{"k": "jawOpen", "v": "x"}]}', b"jawOpen-x|",
                     b'{"Position": {"x": NaN}}', b"=head#a,b,c|"):
            assert adapter.handle(data, 0.0) is None

    class Unreadable:   # the process receiver's channel, holding what its child never sends
        def read(self):
            raise ChannelError("receiver channel: a message of 9999999 bytes (kind 1), over 1048576")

    source = UdpProcessSource(VmcAdapter(), port=0)
    source._inbox = Unreadable()
    source._drain()
    assert source._own["internal_error"] == 1 and isinstance(source.last_error, ChannelError)
