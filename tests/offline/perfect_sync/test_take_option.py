"""``perfect-sync --take``: refused, naming what is wrong, before any work and writing nothing."""

from facepuppet.runtime.cli import main


def test_take_without_the_sheet_or_unreadable_is_refused_writing_nothing(tmp_path, capsys):
    out, pics = tmp_path / "out.npz", tmp_path / "pics"
    bad = tmp_path / "notes.csv"
    bad.write_text("a,b\n1,2\n", encoding="utf-8")
    base = ["perfect-sync", str(tmp_path / "char.npz"), "-o", str(out), "--source", str(tmp_path / "src.npz")]
    assert main([*base, "--take", str(bad)]) == 2
    assert "--take: needs --pictures DIR --sheet" in capsys.readouterr().err
    assert main([*base, "--pictures", str(pics), "--sheet", "--take", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "Live Link Face CSV" in err
    assert not out.exists() and not pics.exists()
