"""Contact sheet: PNG writing, grid layout and the contact-sheet command end to end."""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from PIL import Image

from facepuppet.runtime.commands import contact_sheet
from facepuppet.runtime.render.images import LABEL_HEIGHT, save_png
from facepuppet.runtime.render.images import contact_sheet as make_sheet

from helpers.small_characters import parts_character, sphere_character


def parse(module, argv):
    parser = argparse.ArgumentParser()
    module.register(parser.add_subparsers())
    return parser.parse_args(argv)


def test_save_png_round_trips(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (7, 5, 3), dtype=np.uint8)
    path = save_png(tmp_path / "f.png", rgb)
    np.testing.assert_array_equal(np.asarray(Image.open(path)), rgb)
    with pytest.raises(ValueError, match=r"expected an \(h, w, 3\|4\) uint8 RGB or RGBA array, got \(7, 5\) float64"):
        save_png(tmp_path / "g.png", np.zeros((7, 5)))


def test_save_png_keeps_alpha_and_the_sheet_composites_rgba_cells(tmp_path):
    rgba = np.random.default_rng(1).integers(0, 256, (7, 5, 4), dtype=np.uint8)
    path = save_png(tmp_path / "a.png", rgba)
    back = Image.open(path)
    assert back.mode == "RGBA"
    np.testing.assert_array_equal(np.asarray(back), rgba)
    clear = np.zeros((20, 30, 4), np.uint8)            # nothing drawn: the sheet background shows
    solid = np.full((20, 30, 4), 255, np.uint8)        # opaque white
    sheet = make_sheet([("clear", clear), ("solid", solid)], columns=2)
    assert sheet.shape[2] == 3
    assert tuple(sheet[5, 5]) == (24, 25, 28) and tuple(sheet[5, 35]) == (255, 255, 255)


def test_grid_size_and_labels_drawn():
    cells = [(f"s{i}", np.full((20, 30, 3), 40 * i, np.uint8)) for i in range(5)]
    sheet = make_sheet(cells, columns=2)
    assert sheet.shape == (3 * (20 + LABEL_HEIGHT), 2 * 30, 3)
    np.testing.assert_array_equal(sheet[20 + LABEL_HEIGHT : 40 + LABEL_HEIGHT, 30:60], cells[3][1])
    label_band = sheet[20 : 20 + LABEL_HEIGHT, 0:30]
    assert (label_band.max(axis=2) > 150).any()  # some label text pixels
    with pytest.raises(ValueError, match="is 10x20, expected 30x20"):
        make_sheet(cells + [("odd", np.zeros((20, 10, 3), np.uint8))], columns=2)
    with pytest.raises(ValueError, match="at least one"):
        make_sheet([], columns=2)


@pytest.mark.gl
def test_contact_sheet_command_writes_the_grid(tmp_path, capsys):
    character_path = sphere_character().save(tmp_path / "sphere.npz")
    out = tmp_path / "sheet.png"
    args = parse(contact_sheet, ["contact-sheet", str(character_path), "-o", str(out), "--cell", "64x48",
                                 "--columns", "2", "--path", "gpu"])
    assert args.func(args) == 0
    sheet = np.asarray(Image.open(out))
    # neutral + 2 shapes = 3 cells in 2 columns -> 2 rows
    assert sheet.shape == (2 * (48 + LABEL_HEIGHT), 2 * 64, 3)
    assert "3 cells" in capsys.readouterr().out
    # the jawOpen cell differs from the neutral cell
    neutral, jaw = sheet[:48, :64].astype(int), sheet[:48, 64:128].astype(int)
    assert np.abs(neutral - jaw).sum(axis=2).max() > 50


@pytest.mark.gl
def test_the_character_may_be_given_as_c_like_every_other_command(tmp_path, capsys):
    character_path = sphere_character().save(tmp_path / "sphere.npz")
    out = tmp_path / "sheet.png"
    args = parse(contact_sheet, ["contact-sheet", "-c", str(character_path), "-o", str(out), "--cell", "64x48"])
    assert args.func(args) == 0
    assert Image.open(out).size[0] > 0 and "3 cells" in capsys.readouterr().out
    for argv in (["-o", str(out)], [str(character_path), "-c", str(character_path), "-o", str(out)]):
        args = parse(contact_sheet, ["contact-sheet", *argv])
        with pytest.raises(SystemExit, match="give the character once, as CHARACTER or -c CHARACTER"):
            args.func(args)


def test_cell_option_is_validated():
    with pytest.raises(SystemExit):
        parse(contact_sheet, ["contact-sheet", "x.npz", "-o", "y.png", "--cell", "big"])



def test_face_framing_shows_the_face_larger_than_head_framing(egl_ctx, ict_character):
    """ICT's neck and shoulders make head framing much wider than the face."""
    from facepuppet.runtime.render.renderer import FaceRenderer

    covered = {}
    for framing in ("head", "face"):
        r = FaceRenderer(egl_ctx, ict_character, 160, 160, path="cpu", log=lambda s: None, framing=framing)
        r.draw(np.zeros(ict_character.n_shapes, np.float32))
        image = r.read_pixels().astype(int)
        r.close()
        covered[framing] = (np.abs(image - image[0, 0]).sum(axis=2) > 30).mean()
    assert covered["face"] > 1.3 * covered["head"]


@pytest.mark.gl
def test_a_vrm_characters_sheet_has_a_cell_per_expression_and_its_credits_under_it(tmp_path, capsys):
    c = parts_character()  # one shape "s" (moves the top-left vertex), one expression Blink binding it at 0.5
    path = c.save(tmp_path / "parts.npz")
    out = tmp_path / "sheet.png"
    args = parse(contact_sheet, ["contact-sheet", str(path), "-o", str(out), "--cell", "64x48", "--columns", "3",
                                 "--path", "cpu"])
    assert args.func(args) == 0
    assert "3 cells (1 shapes, 1 expressions + neutral)" in capsys.readouterr().out
    sheet = np.asarray(Image.open(out))
    cells = 48 + LABEL_HEIGHT
    assert sheet.shape[0] > cells and sheet.shape[1] == 3 * 64  # one row of cells and a footer under it
    neutral, shape, expression = (sheet[:48, k * 64:(k + 1) * 64].astype(int) for k in range(3))
    assert np.abs(expression - neutral).max() > 30  # Blink moves its shape by half
    assert np.abs(expression - shape).max() > 30    # ... not all the way
    footer = sheet[cells:]
    assert (footer.max(axis=2) > 150).any()  # the credits text
    args = parse(contact_sheet, ["contact-sheet", str(path), "-o", str(tmp_path / "s2.png"), "--cell", "64x48",
                                 "--no-expressions", "--path", "cpu"])
    assert args.func(args) == 0
    assert "2 cells (1 shapes + neutral)" in capsys.readouterr().out
