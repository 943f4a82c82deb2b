"""The jobs file of ``facepuppet batch``: jobs and their ids, and every refusal naming the file and the key
(exit 2, before any cluster starts); a job's result is skipped only while its inputs, options and version
match, and a failed job leaves nothing that passes for a result."""

from __future__ import annotations

import json

import numpy as np
import pytest

from facepuppet.runtime import cli

from facepuppet.offline.batch.job_run import PARTIAL, run_job
from facepuppet.offline.batch.jobs import JobsFileError, load_jobs, slug
from facepuppet.offline.batch.manifest import input_hashes, is_done
from helpers.batch_library import library, write_take


def _jobs_file(tmp_path, text: str):
    library(tmp_path, n_takes=2)
    path = tmp_path / "jobs.toml"
    path.write_text(text)
    return path


def test_groups_cross_takes_with_characters_with_readable_stable_ids(tmp_path):
    path = _jobs_file(tmp_path, '[groups.Rig-v2]\ntakes = ["takes/*.fps"]\ncharacters = ["chars/sphere.npz"]\n'
                                'fps = 30\nconfig = "live.toml"\n[groups.Rig-v2.outputs]\nframes = [1, 0.5]\n'
                                '[groups.other]\ntakes = "takes/take0.fps"\ncharacters = ["chars/*.npz"]\n')
    (tmp_path / "live.toml").write_text("")
    jobs = load_jobs(path)
    assert [j.id for j in jobs] == ["take0--sphere--rig-v2", "take1--sphere--rig-v2", "take0--bare--other",
                                    "take0--sphere--other"]
    first = jobs[0]
    assert first.outputs.frames == (0.5, 1.0) and first.path == "gpu"
    assert ["--fps", "30.0"] == list(first.replay_args[first.replay_args.index("--fps"):][:2])
    assert first.files[-1] == tmp_path / "live.toml" and first.options["config"] == "live.toml"
    assert load_jobs(path) == jobs  # stable
    assert slug("My Take (v2).final") == "my-take-v2-final"


def test_two_takes_of_one_stem_get_distinct_ids(tmp_path):
    write_take(tmp_path / "a" / "take.fps", 0.2)
    write_take(tmp_path / "b" / "take.fps", 0.2)
    path = _jobs_file(tmp_path, '[groups.g]\ntakes = ["a/take.fps", "b/take.fps"]\ncharacters = "chars/bare.npz"\n')
    ids = [j.id for j in load_jobs(path)]
    assert len(set(ids)) == 2 and all(i.startswith("take--bare--g--") for i in ids)


G = "[groups.g]\ntakes = ['takes/*.fps']\ncharacters = ['chars/*.npz']\n"


@pytest.mark.parametrize(("text", "message"), [
    (G + "sise = '64x48'\n", "groups.g.sise: unknown key"),
    ("[groups.g]\ntakes = ['takes/*.wav']\ncharacters = ['chars/*.npz']\n", "groups.g.takes: 'takes/*.wav' matches no"),
    ("[groups.g]\ntakes = ['../x/*.fps']\ncharacters = ['chars/*.npz']\n",
     "groups.g.takes: '../x/*.fps' leads outside"),
    (G + "fps = 'fast'\n", "groups.g.fps: expected a"),
    (G + "path = 'auto'\n", "groups.g.path: expected"),
    (G + "[groups.g.outputs]\nframes = [-1]\n",
     "groups.g.outputs.frames: expected times"),
    (G + "[groups.g.outputs]\nweights = false\n",
     "groups.g.outputs: every output is off"),
    ("[group.g]\n", "group: unknown key"),
    ("[groups.g\n", "not a TOML jobs file"),
    # replay's own refusal, named by group
    (G + "pipeline = false\ncalibrate = true\n",
     "groups.g: --no-pipeline"),
])
def test_a_bad_jobs_file_exits_2_naming_the_file_and_the_key(tmp_path, capsys, text, message):
    path = _jobs_file(tmp_path, text)
    assert cli.main(["batch", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"{path}: " in err and message in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_load_jobs_raises_its_own_error(tmp_path):
    path = _jobs_file(tmp_path, "[groups.g]\ntakes = 3\ncharacters = ['chars/*.npz']\n")
    with pytest.raises(JobsFileError, match="groups.g.takes: expected a file name or glob"):
        load_jobs(path)


@pytest.mark.gl
def test_a_result_is_skipped_only_while_inputs_options_and_version_match(tmp_path):
    path = library(tmp_path / "lib", n_takes=1, seconds=0.3)
    job = load_jobs(path)[0]
    out = tmp_path / "out"
    assert not is_done(job, input_hashes(job), out)
    report = run_job(job, out)
    assert report["status"] == "ok" and report["ticks"] == 9, report
    assert is_done(job, input_hashes(job), out)
    assert not (out / PARTIAL).exists() or not any((out / PARTIAL).iterdir())
    manifest = json.loads((out / job.id / "manifest.json").read_text())
    assert manifest["figures"]["ticks"] == 9 and np.load(out / job.id / "weights.npy").shape == (9, 2)
    # another option, another take, another version: run again
    path.write_text(path.read_text().replace('size = "64x48"', 'size = "64x40"'))
    assert not is_done(load_jobs(path)[0], input_hashes(job), out)
    take = job.take.read_bytes()
    write_take(job.take, 0.3, phase=1.0)
    assert not is_done(job, input_hashes(job), out)
    job.take.write_bytes(take)
    assert is_done(job, input_hashes(job), out)
    (out / job.id / "manifest.json").write_text(json.dumps({**manifest, "facepuppet": "0.0.1"}))
    assert not is_done(job, input_hashes(job), out)
    (out / job.id / "manifest.json").unlink()  # a folder without a manifest is not a result
    assert not is_done(job, input_hashes(job), out)


@pytest.mark.gl
def test_a_failed_job_leaves_no_folder_and_replaces_no_result(tmp_path):
    path = library(tmp_path / "lib", n_takes=1, seconds=0.3)
    job = load_jobs(path)[0]
    out = tmp_path / "out"
    assert run_job(job, out)["status"] == "ok"
    before = (out / job.id / "weights.npy").read_bytes()
    job.take.write_bytes(b"FPS1 damaged")
    report = run_job(job, out)
    assert report["status"] == "failed" and str(job.take) in report["message"], report
    assert (out / job.id / "weights.npy").read_bytes() == before  # the earlier result stays whole
    assert not any((out / PARTIAL).iterdir())
    assert not is_done(job, input_hashes(job), out)  # but no longer counts for the changed take


@pytest.mark.gl
def test_frames_are_the_first_ticks_at_or_after_their_times_and_a_time_past_the_end_draws_none(tmp_path):
    path = library(tmp_path / "lib", n_takes=1, seconds=0.3, outputs="weights = false\nframes = [0.05, 0.1, 9]")
    job = load_jobs(path)[0]
    assert run_job(job, tmp_path / "out")["status"] == "ok"
    outputs = json.loads((tmp_path / "out" / job.id / "manifest.json").read_text())["outputs"]
    assert outputs["frame_ticks"] == [2, 3] and outputs["frame_times"] == [0.05, 0.1]  # ticks at k / 30 s
    assert outputs["frames_past_end"] == [9.0] and "weights" not in outputs
    assert sorted(p.name for p in (tmp_path / "out" / job.id / "frames").iterdir()) == ["frame_00000.png",
                                                                                       "frame_00001.png"]
