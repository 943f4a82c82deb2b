"""The picture quality: what --quality and --msaa choose, live and for pictures kept, through real runs."""

from __future__ import annotations

import numpy as np
import pytest

from facepuppet.runtime.cli import main
from facepuppet.runtime.render.quality import BUDGET_SHARE, budget_note, choose_quality, is_software

from helpers.logs import session_log
from helpers.small_characters import sphere_character
from helpers.udp_helpers import free_udp_port

LLVMPIPE = "llvmpipe (LLVM 15.0.6, 256 bits)"
GPU = "NVIDIA H200/PCIe/SSE2"


def test_software_rasterisers_are_told_from_gpus():
    for name in (LLVMPIPE, "softpipe", "Google SwiftShader", "Apple Software Renderer", "GDI Generic"):
        assert is_software(name), name
    for name in (GPU, "AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 16.0.6, DRM 3.54)", "Mesa Intel(R) UHD", None):
        assert not is_software(name), name


@pytest.mark.parametrize("msaa, quality, renderer, live, expected, layers", [
    (None, "auto", LLVMPIPE, True, 0, False),   # live on a software rasteriser: both off, said once
    (None, "auto", GPU, True, 4, True),         # live on a GPU: full (the draw is timed against the budget after)
    (None, "auto", LLVMPIPE, False, 4, True),   # pictures kept as files: full quality
    (None, "full", LLVMPIPE, True, 4, True),
    (None, "fast", GPU, False, 0, False),
    (2, "auto", LLVMPIPE, True, 2, False),      # an explicit --msaa wins for the samples
    (2, "fast", GPU, True, 2, False),
    (0, "full", GPU, False, 0, True),
])
def test_choose_quality(msaa, quality, renderer, live, expected, layers):
    chosen = choose_quality(msaa, quality, renderer, live)
    assert (chosen.msaa, chosen.subtle_layers) == (expected, layers)
    lowered = quality == "auto" and live and not layers  # what auto lowered is said; what was asked is not
    assert bool(chosen.note) == lowered
    if lowered:
        assert "--quality full" in chosen.note and "llvmpipe" in chosen.note and "eye layers" in chosen.note
        assert ("MSAA" in chosen.note) == (msaa is None)


def test_budget_note_only_when_the_draw_takes_more_than_its_share():
    budget = 1000 / 60
    assert budget_note(BUDGET_SHARE * budget * 0.99, budget, 4) == ""
    assert budget_note(BUDGET_SHARE * budget * 1.01, budget, 0) == ""  # nothing left to lower
    note = budget_note(BUDGET_SHARE * budget * 1.01, budget, 4)
    assert "MSAA off" in note and "--msaa 4" in note


def run(tmp_path, *extra, out=False):
    char = tmp_path / "sphere.npz"
    if not char.exists():
        sphere_character().save(char)
    args = ["run", "-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}", "--headless",
            "--duration", "0.2", "--size", "96x72", "--fps", "20", "--draw", "tick", "--path", "cpu", *extra]
    if out:
        args += ["--out", str(tmp_path / f"frames{len(list(tmp_path.iterdir()))}")]
    with session_log() as lines:
        assert main(args) == 0
    return "\n".join(lines)


def smoothness(folder):
    """Distinct grey levels along the sphere's silhouette: MSAA makes intermediate ones."""
    from PIL import Image

    image = np.asarray(Image.open(sorted(folder.glob("*.png"))[-1]).convert("L"), dtype=int)
    return len(np.unique(image))


def test_a_live_run_on_llvmpipe_draws_without_msaa_and_says_so_once(egl_ctx, tmp_path):
    if not is_software(egl_ctx.info["GL_RENDERER"]):
        pytest.skip(f"the test machine's OpenGL is a GPU ({egl_ctx.info['GL_RENDERER']}), not a software "
                    "rasteriser")
    text = run(tmp_path)
    assert text.count("picture quality auto") == 1 and "MSAA off" in text
    assert "picture quality" not in run(tmp_path, "--quality", "full")
    text = run(tmp_path, "--msaa", "4")
    assert "MSAA off" not in text and text.count("eye layers") == 1


def test_pictures_kept_as_files_are_drawn_with_msaa_and_fast_without(egl_ctx, tmp_path):
    text = run(tmp_path, out=True)
    assert "picture quality" not in text  # files: full quality, nothing lowered
    full = sorted(tmp_path.glob("frames*"))[-1]
    run(tmp_path, "--quality", "fast", out=True)
    fast = sorted(tmp_path.glob("frames*"))[-1]
    assert smoothness(full) > smoothness(fast)
