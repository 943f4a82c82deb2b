"""A batch run against its goldens (``compare_runs``, ``write_report``) on job folders of real replays.

Three takes on one small character: one drives ``jawOpen`` only, one ``puff`` only, one both. The golden run,
the same jobs replayed again (nothing changed), and the jobs replayed on the character with ``puff`` made
twice as wide: the report must name exactly the takes that drive ``puff``.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from facepuppet.offline.batch.golden import compare_runs
from facepuppet.offline.batch.golden_report import REPORT_JSON, REPORT_MD, write_report
from helpers.batch_job_folders import edit_manifest, replay_job, write_take
from helpers.small_characters import sphere_character

pytestmark = [pytest.mark.gl, pytest.mark.slow]   # nine headless replays

TAKES = {"jaw": {"jawOpen": 0.8}, "puff": {"puff": 0.9}, "both": {"jawOpen": 0.6, "puff": 0.7}}
PICTURES = Path("/tmp/p32-golden")   # a copy of the report to look at


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("golden")
    character = sphere_character()
    golden_char = character.save(root / "sphere.npz")
    s = character.shape_names.index("puff")
    lo, hi = character.delta_offsets[s], character.delta_offsets[s + 1]
    positions = character.delta_positions.copy()
    positions[lo:hi] *= 2.0
    changed_char = dataclasses.replace(character, delta_positions=positions).save(root / "sphere_puff2.npz")
    takes = {name: write_take(root / f"{name}.fps", drives) for name, drives in TAKES.items()}
    out = {}
    for run, char in (("golden", golden_char), ("same", golden_char), ("changed", changed_char)):
        for name, take in takes.items():
            replay_job(root / run, f"{name}-sphere", take, char)
        out[run] = root / run
    return out


def test_a_run_replayed_again_reports_nothing_changed(runs):
    report = compare_runs(runs["same"], runs["golden"])
    assert [j.job for j in report.jobs] == ["both-sphere", "jaw-sphere", "puff-sphere"]
    assert report.changed == []
    for job in report.jobs:
        assert job.problems == [] and job.inputs_changed == [] and job.notes == []
        assert set(job.channel_delta) == {"jawOpen", "puff"} and job.max_weight_delta == 0.0
        assert len(job.frames) == 12 and all(f.over == 0.0 and f.mean_abs == 0.0 for f in job.frames)


def test_a_changed_shape_names_exactly_the_jobs_whose_takes_drive_it(runs):
    report = compare_runs(runs["changed"], runs["golden"])
    assert sorted(j.job for j in report.changed) == ["both-sphere", "puff-sphere"]
    by_id = {j.job: j for j in report.jobs}
    for job in report.jobs:   # the character's content changed under every job; its weights under none
        assert job.inputs_changed == ["character (sphere.npz -> sphere_puff2.npz)"]
        assert job.max_weight_delta == 0.0 and job.problems == []
    jaw = by_id["jaw-sphere"]
    assert all(f.over == 0.0 and f.mean_abs == 0.0 for f in jaw.frames) and not jaw.changed
    # most changed first: the take that swings puff furthest ranks above the one that also drives the jaw
    puff, both = by_id["puff-sphere"], by_id["both-sphere"]
    assert [j.job for j in report.changed] == sorted(["puff-sphere", "both-sphere"], key=lambda i: -by_id[i].score)
    assert puff.score > 1 and both.score > 1
    assert report.changed[0].worst_frames(1)[0].over > report.pixel_tol


def test_the_report_shows_the_worst_frames_side_by_side(runs, tmp_path):
    report = compare_runs(runs["changed"], runs["golden"])
    written = write_report(report, tmp_path / "report")
    md = (tmp_path / "report" / REPORT_MD).read_text()
    assert "**2 changed beyond tolerance**" in md and "| 1 | " in md and "| 3 | " not in md
    assert "jaw-sphere" not in md.split("within tolerance with")[0].split("| rank |")[1]
    thumbs = sorted(p for p in written if p.suffix == ".png")
    assert len(thumbs) == 6   # three worst frames of each changed job
    for p in thumbs:
        assert f"]({p.relative_to(tmp_path / 'report').as_posix()})" in md
        with Image.open(p) as im:
            assert im.size[0] == 3 * 192 and im.size[1] > 192
        cells = np.asarray(Image.open(p).convert("RGB"))[:192]
        golden, new, heat = cells[:, :192], cells[:, 192:384], cells[:, 384:]
        assert np.any(golden != new) and heat.max() > 0   # the change is visible, and its heat drawn
    doc = json.loads((tmp_path / "report" / REPORT_JSON).read_text())
    assert doc["changed"] == [j.job for j in report.changed] and doc["jobs"] == 3
    worst = [f for r in doc["results"] if r["changed"] for f in r["worst_frames"]]
    assert len(worst) == 6 and all(f["t"] == pytest.approx(f["index"] / 30) for f in worst)   # a 30 Hz take
    shutil.rmtree(PICTURES / "report", ignore_errors=True)
    shutil.copytree(tmp_path / "report", PICTURES / "report")


def test_missing_jobs_on_either_side_and_frames_on_another_path(runs, tmp_path):
    new = tmp_path / "new"
    shutil.copytree(runs["same"], new)
    shutil.rmtree(new / "jaw-sphere")
    shutil.copytree(new / "puff-sphere", new / "extra")
    edit_manifest(new / "extra", job="extra")
    edit_manifest(new / "both-sphere", path="gpu")
    report = compare_runs(new, runs["golden"])
    by_id = {j.job: j for j in report.jobs}
    assert by_id["jaw-sphere"].problems == ["missing from the new run"]
    assert by_id["extra"].problems == ["not in the golden run"]
    both = by_id["both-sphere"]
    assert not both.changed and not both.frames_comparable and both.frames == []
    assert "frames not comparable: drawn on the gpu path, the golden on the cpu path" in both.notes
    assert [j.job for j in report.changed] == ["extra", "jaw-sphere"]   # structural changes, then by id


def test_a_weight_change_ranks_by_its_size_and_a_failed_job_is_a_change(runs, tmp_path):
    new = tmp_path / "new"
    shutil.copytree(runs["same"], new)
    for job, delta in (("jaw-sphere", 0.01), ("puff-sphere", 0.3)):
        w = np.load(new / job / "weights.npy")
        w[5, 0] += delta
        np.save(new / job / "weights.npy", w)
    edit_manifest(new / "both-sphere", status="failed")
    report = compare_runs(new, runs["golden"])
    assert [j.job for j in report.changed] == ["both-sphere", "puff-sphere", "jaw-sphere"]
    assert report.changed[0].problems == ["failed in the new run (status 'failed')"]
    assert report.changed[1].channel_delta["jawOpen"] == pytest.approx(0.3, abs=1e-6)
    assert report.changed[1].worst_channel == "jawOpen"
    assert compare_runs(new, runs["golden"], weight_tol=0.5).changed[1:] == []
