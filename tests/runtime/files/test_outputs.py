"""One policy for every command's outputs: an existing one is refused naming --force, before any work;
files are written atomically; several outputs of one command land together or not at all."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from facepuppet.runtime import cli
from facepuppet.runtime.files.outputs import OUTPUT_OPTIONS, SENT_OUTPUTS, OutputSet, atomic_path, output_actions


def _commands():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def _dummy_argv(command: str, parser: argparse.ArgumentParser, skip: str, tmp_path) -> list[str]:
    """Values for every positional and required option of ``parser`` (inputs that do not exist)."""
    argv = [command]
    for action in parser._actions:
        if action.dest in ("help", skip) or isinstance(action, argparse._StoreTrueAction):
            continue
        if action.option_strings and not action.required:
            continue
        n = action.nargs if isinstance(action.nargs, int) else 1
        value = [str(action.choices[0]) if action.choices else str(tmp_path / f"absent_{action.dest}")] * n
        argv += ([action.option_strings[0]] if action.option_strings else []) + value
    return argv


def _output_cases():
    cases = []
    for name, parser in _commands().items():
        for dest, kind, flag in output_actions(parser):
            cases.append((name, dest, kind, flag))
    return cases


CASES = _output_cases()


def test_the_walk_finds_the_outputs_of_every_command():
    found = {(c, d) for c, d, _, _ in CASES}
    expected = {("run", "record"), ("run", "out"), ("run", "dump_weights"), ("replay", "out"),
                ("replay", "dump_weights"), ("demo", "out"), ("manipulate", "out"), ("contact-sheet", "output"),
                ("import-rig", "output"), ("train-actor", "output"), ("train-actor", "pictures"),
                ("retarget-actor", "output"), ("retarget-actor", "pictures"), ("fit-elastic", "output"),
                ("fit-elastic", "save_controls"), ("fit-elastic", "pictures"), ("clone-elastic", "output"),
                ("clone-elastic", "pictures"), ("build-gestures", "output"), ("synthesize-gestures", "output"),
                ("synthesize-gestures", "pictures"), ("transfer-detail", "output"),
                ("transfer-detail", "gestures_out"), ("transfer-detail", "pictures"), ("fit-retarget", "output")}
    assert expected <= found, sorted(expected - found)
    # every option that looks like an output is one the policy knows, but for the one output that is resumed by
    # design: batch's --out keeps the job folders of earlier runs and skips the jobs whose manifests still match
    # (each job folder is replaced atomically; tests/offline/batch/test_batch.py)
    resumed = {("batch", "out_dir")}
    for name, parser in _commands().items():
        for action in parser._actions:
            if any(s in ("-o", "--output", "--out", "--record", "--dump-weights") for s in action.option_strings):
                assert action.dest in OUTPUT_OPTIONS or (name, action.dest) in resumed, (name, action.dest)


def test_every_output_sent_rather_than_written_is_known_to_the_policy():
    """The outputs that go to the network or a device are named in the policy (no file to refuse), and none is
    also a file output."""
    sent_flags = ("--vmc-out", "--llf-out", "--events-out", "--stream", "--virtual-camera")
    seen = set()
    for name, parser in _commands().items():
        for action in parser._actions:
            if any(s in sent_flags for s in action.option_strings):
                assert action.dest in SENT_OUTPUTS and action.dest not in OUTPUT_OPTIONS, (name, action.dest)
                seen.add(action.dest)
    assert seen == set(SENT_OUTPUTS)


@pytest.mark.parametrize("command, dest, kind, flag", CASES, ids=[f"{c}:{f}" for c, _, _, f in CASES])
def test_every_output_that_exists_is_refused_naming_force_before_any_work(command, dest, kind, flag, tmp_path,
                                                                        capsys):
    parser = _commands()[command]
    assert any("--force" in a.option_strings for a in parser._actions), f"{command} has no --force"
    existing = tmp_path / ("existing_dir" if kind == "dir" else "existing.out")
    if kind == "dir":
        existing.mkdir()
        (existing / "frame_00000.png").write_bytes(b"kept")
    else:
        existing.write_bytes(b"kept")
    argv = _dummy_argv(command, parser, dest, tmp_path) + [flag, str(existing)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"{flag} {existing}" in err and "--force" in err and "Traceback" not in err, err
    kept = existing / "frame_00000.png" if kind == "dir" else existing
    assert kept.read_bytes() == b"kept"                           # nothing touched
    assert sorted(p.name for p in tmp_path.iterdir()) == [existing.name]   # nothing else written


def test_clone_elastic_refuses_the_character_it_would_write_beside_its_table(tmp_path, capsys):
    (tmp_path / "clone_character.npz").write_bytes(b"kept")
    assert cli.main(["clone-elastic", str(tmp_path / "e.npz"), "demo", "-o", str(tmp_path / "clone.npz")]) == 2
    err = capsys.readouterr().err
    assert "clone_character.npz: exists; pass --force" in err


def test_bench_json_is_refused_before_the_benchmark_runs(tmp_path, capsys):
    out = tmp_path / "bench.json"
    out.write_text("kept")
    assert cli.main(["bench", "render", "-c", str(tmp_path / "absent.npz"), "--json", str(out)]) == 2
    assert "--json" in capsys.readouterr().err and out.read_text() == "kept"


def test_outputs_that_cannot_be_written_are_refused(tmp_path, capsys):
    argv = ["contact-sheet", str(tmp_path / "c.npz"), "-o"]
    assert cli.main(argv + [str(tmp_path / "no" / "sheet.png")]) == 2
    assert "the folder" in capsys.readouterr().err
    assert cli.main(argv + [str(tmp_path)]) == 2
    assert "is a folder; name a file" in capsys.readouterr().err
    assert cli.main(["replay", str(tmp_path / "s.fps"), "-c", str(tmp_path / "c.npz"), "--dump-weights",
                     str(tmp_path / "w.npy"), "--out", str(tmp_path / "w.npy")]) == 2
    assert "the same path as" in capsys.readouterr().err


def test_atomic_path_leaves_the_old_file_when_writing_fails(tmp_path):
    path = tmp_path / "w.npy"
    np.save(path, np.zeros(3))
    with pytest.raises(RuntimeError, match="disk full"):
        with atomic_path(path) as temp:
            temp.write_bytes(b"half")
            raise RuntimeError("disk full")
    np.testing.assert_array_equal(np.load(path), np.zeros(3))
    assert [p.name for p in tmp_path.iterdir()] == ["w.npy"]
    with atomic_path(path) as temp:
        np.save(temp, np.ones(2))
    np.testing.assert_array_equal(np.load(path), np.ones(2))


def test_an_output_set_lands_all_its_files_or_none(tmp_path):
    a, b = tmp_path / "a.npz", tmp_path / "b.json"
    with pytest.raises(ValueError, match="the second"):
        with OutputSet() as outputs:
            outputs.path(a).write_text("first")
            outputs.path(b)
            raise ValueError("the second failed")
    assert list(tmp_path.iterdir()) == []                       # not the first alone
    with OutputSet() as outputs:
        outputs.path(a).write_text("first")
        outputs.path(b).write_text("second")
    assert a.read_text() == "first" and b.read_text() == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.npz", "b.json"]


def test_synthesize_gestures_onto_an_existing_output_is_refused_and_force_replaces_it(tmp_path, capsys):
    import wave

    from facepuppet.runtime.recording.session import read_session

    from helpers.gesture_dbs import small_db

    db = tmp_path / "g.npz"
    small_db(db)
    wav = tmp_path / "speech.wav"
    t = np.arange(16000) / 16000
    with wave.open(str(wav), "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(16000)
        w.writeframes((0.3 * np.sin(2 * np.pi * 200 * t) * 32767).astype("<i2").tobytes())
    out = tmp_path / "take.fps"
    out.write_bytes(b"kept")
    assert cli.main(["synthesize-gestures", str(db), str(wav), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exists; pass --force" in err and "Traceback" not in err and out.read_bytes() == b"kept"
    assert cli.main(["synthesize-gestures", str(db), str(wav), "-o", str(out), "--force"]) == 0
    assert len(read_session(out).frames) > 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.npz", "speech.wav", "take.fps"]   # no temp left


@pytest.mark.gl
def test_the_demo_default_folder_follows_the_policy(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = ["demo", "--headless", "--duration", "0.3", "--fps", "10", "--size", "64x48", "--no-frames"]
    assert cli.main(argv) == 0 and (tmp_path / "demo-out" / "contact_sheet.png").is_file()
    capsys.readouterr()
    assert cli.main(argv) == 2
    assert "--out (default) demo-out: the folder exists and is not empty; pass --force" in capsys.readouterr().err
    assert cli.main(argv + ["--force"]) == 0


def test_atomic_files_get_the_permissions_of_a_plain_write(tmp_path):
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    with atomic_path(tmp_path / "atomic.txt") as temp:
        temp.write_text("x")
    assert (tmp_path / "atomic.txt").stat().st_mode & 0o777 == plain.stat().st_mode & 0o777
