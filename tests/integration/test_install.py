"""Install from a clean clone: the wheel carries the shaders and the command works from it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.slow  # the module's fixture clones the repository and builds a wheel


def run(cmd, **kw):
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kw)
    assert result.returncode == 0, f"{cmd} failed:\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    return result


@pytest.fixture(scope="module")
def installed_wheel(tmp_path_factory):
    if not (REPO / ".git").exists() or shutil.which("git") is None:
        pytest.skip("not a git checkout: the clean-clone install test needs git and the repository history")
    tmp = tmp_path_factory.mktemp("install")
    clone = tmp / "clone"
    run(["git", "clone", "--quiet", str(REPO), str(clone)])
    run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
         "-w", str(tmp / "dist"), str(clone)])
    wheels = list((tmp / "dist").glob("facepuppet-*.whl"))
    assert len(wheels) == 1, wheels
    site = tmp / "site"
    run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--target", str(site), str(wheels[0])])
    return tmp, site


def in_wheel(site: Path, tmp: Path, code: str):
    """Run Python with the installed wheel first on the path and the checkout off it."""
    env = {**os.environ, "PYTHONPATH": str(site)}
    return run([sys.executable, "-c", code], cwd=tmp, env=env)


def test_wheel_imports_from_its_own_files_and_carries_the_shaders(installed_wheel):
    tmp, site = installed_wheel
    out = in_wheel(site, tmp, (
        "import facepuppet, facepuppet.runtime, facepuppet.offline\n"
        "from importlib.resources import files\n"
        "print(facepuppet.__file__)\n"
        "print(sorted(p.name for p in files('facepuppet.shaders').iterdir() if p.name.endswith('.glsl')))\n"
    )).stdout.splitlines()
    assert out[0].startswith(str(site)), f"imported {out[0]}, not the installed wheel"
    assert "face.glsl" in out[1]


def test_wheel_compiles_its_shaders_on_a_real_context(installed_wheel, egl_ctx):
    tmp, site = installed_wheel
    out = in_wheel(site, tmp, (
        "import moderngl\n"
        "from facepuppet.runtime.render import shader_loader\n"
        "ctx = moderngl.create_standalone_context(backend='egl', require=330)\n"
        "prog = shader_loader.load_program(ctx, 'face.glsl')\n"
        "print(shader_loader.__file__)\n"
        "print(ctx.error)\n"
    )).stdout.splitlines()
    assert out[0].startswith(str(site))
    assert out[1] == "GL_NO_ERROR"


def test_console_command_lists_runtime_and_offline_commands(installed_wheel):
    tmp, site = installed_wheel
    out = in_wheel(site, tmp, "from facepuppet.runtime.cli import main; main(['--help'])")
    for command in ("demo", "replay", "contact-sheet", "bench", "import-rig"):
        assert command in out.stdout, f"{command} missing from --help:\n{out.stdout}"


def test_wheel_carries_every_module_of_every_sub_package(installed_wheel):
    tmp, site = installed_wheel
    for folder in ("runtime", "offline"):
        ours = {p.relative_to(REPO / folder).as_posix() for p in (REPO / folder).rglob("*.py")
                if "_top" not in p.parts and "__pycache__" not in p.parts}
        wheel = {p.relative_to(site / "facepuppet" / folder).as_posix()
                 for p in (site / "facepuppet" / folder).rglob("*.py")}
        assert ours - wheel == set(), f"{folder}/ modules missing from the wheel (add the package to pyproject.toml)"
