"""The picture options of the commands: --background, --framing, --msaa, --credits, end to end through ``run``."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.cli import main
from facepuppet.runtime.render.options import parse_background, render_options

from helpers.logs import said
from helpers.part_characters import figure
from helpers.udp_helpers import free_udp_port


def test_background_values():
    assert parse_background("transparent")[1] is True
    assert parse_background("0.5, 0.25,1") == ((0.5, 0.25, 1.0), False)
    assert parse_background("255,0,51") == ((1.0, 0.0, 0.2), False)
    for bad in ("red", "1,2", "300,0,0", "-1,0,0"):
        with pytest.raises(ValueError, match="--background: expected 'transparent' or R,G,B"):
            parse_background(bad)


def test_render_options_defaults_and_msaa_check():
    import argparse

    opts = render_options(argparse.Namespace())
    assert (opts.framing, opts.transparent, opts.msaa, opts.quality, opts.credits) == \
        ("head", False, None, "auto", False)
    assert opts.renderer_kwargs()["msaa"] == 4  # a picture that is kept: full quality
    assert render_options(argparse.Namespace(quality="fast")).renderer_kwargs()["msaa"] == 0
    assert render_options(argparse.Namespace(quality="fast", msaa=2)).renderer_kwargs()["msaa"] == 2
    with pytest.raises(ValueError, match="--msaa"):
        render_options(argparse.Namespace(msaa=-2))
    with pytest.raises(ValueError, match="--quality"):
        render_options(argparse.Namespace(quality="best"))


def run_figure(tmp_path, capsys, *extra):
    char = figure().save(tmp_path / "figure.npz")
    out = tmp_path / ("frames" + "".join(extra).replace("-", "").replace(",", ""))
    code = main(["run", "-c", str(char), "--input", "vmc", "--listen", f"127.0.0.1:{free_udp_port()}",
                 "--headless", "--duration", "0.2", "--size", "120x90", "--draw", "tick", "--fps", "20",
                 "--path", "cpu", "--out", str(out), *extra])
    text = said(capsys)
    assert code == 0, text
    frames = sorted(out.glob("frame_*.png"))
    assert frames
    return Image.open(frames[-1]), text


@pytest.mark.gl
def test_run_transparent_background_writes_rgba_frames_and_prints_and_draws_the_credits(tmp_path, capsys):
    plain, text = run_figure(tmp_path, capsys, "--background", "transparent", "--framing", "body")
    assert "credits: Test figure by Nobody, CC0" in text
    a = np.asarray(plain)
    assert plain.mode == "RGBA" and a[0, 0, 3] == a[-1, -1, 3] == 0
    assert a[45, 60, 3] == 255                      # the body, in the middle of the body framing
    credited, _ = run_figure(tmp_path, capsys, "--background", "transparent", "--framing", "body", "--credits")
    c = np.asarray(credited)
    corner = (slice(90 - 20, 90 - 8), slice(8, 36))  # the label box sits 8 px in from the bottom-left
    assert (a[corner][..., 3] == 0).all() and (c[corner][..., 3] > 100).all()
    assert (c[corner][..., :3].max(axis=2) > 200).any()   # light text in the box


@pytest.mark.gl
def test_run_framing_head_shows_the_head_larger_than_body(tmp_path, capsys):
    body, _ = run_figure(tmp_path, capsys, "--framing", "body", "--background", "0,0,0")
    head, _ = run_figure(tmp_path, capsys, "--background", "0,0,0")      # default: head
    drawn = lambda im: (np.asarray(im.convert("RGB")).max(axis=2) > 0)  # noqa: E731
    rows = lambda m: np.flatnonzero(m.any(axis=1))  # noqa: E731
    assert np.asarray(body)[0, 0].tolist() == [0, 0, 0]
    # body framing: the figure spans most of the height but is narrow; head framing: the head fills the frame
    assert drawn(head).sum() > 2 * drawn(body).sum()
    assert len(rows(drawn(body))) > 60


def test_bad_background_exits_2(tmp_path, capsys):
    char = figure().save(tmp_path / "figure.npz")
    code = main(["run", "-c", str(char), "--input", "vmc", "--headless", "--duration", "0.1",
                 "--background", "purple"])
    assert code == 2 and "--background: expected" in capsys.readouterr().err
