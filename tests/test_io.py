"""servoscope's one atomic writer: a file is replaced whole or left as it was."""

from __future__ import annotations

import json

import pytest

from servoscope._io import (atomic_path, staged_files, staged_folder, write_bytes_atomic, write_json_atomic,
                            write_text_atomic)
from servoscope.errors import ServoscopeError


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "result.json"
    path.write_text("old\n")
    with pytest.raises(RuntimeError):
        with atomic_path(path) as tmp:
            tmp.write_text("half of the new")
            raise RuntimeError("killed half-way")
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.json"]


def test_the_temporary_name_keeps_the_suffix_and_is_renamed(tmp_path):
    path = tmp_path / "figure.svg"
    with atomic_path(path) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".svg" and tmp.name.startswith(".")
        assert not path.exists()  # nothing at the destination until the block ends
        tmp.write_bytes(b"<svg/>")
    assert path.read_bytes() == b"<svg/>"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.svg"]


def test_text_bytes_and_json(tmp_path):
    write_text_atomic(tmp_path / "a.txt", "τ = 1 ms\n")
    write_bytes_atomic(tmp_path / "b.bin", b"\x00\x01")
    write_json_atomic(tmp_path / "c.json", {"x": 1.5})
    assert (tmp_path / "a.txt").read_text(encoding="utf-8") == "τ = 1 ms\n"
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert json.loads((tmp_path / "c.json").read_text()) == {"x": 1.5}
    assert len(list(tmp_path.iterdir())) == 3


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_staged_folder_appears_whole_at_the_end(tmp_path):
    out = tmp_path / "a" / "out"
    with staged_folder(out) as stage:
        assert stage.parent == out.parent and stage.name.startswith("out.tmp-") and stage.is_dir()
        (stage / "tracks").mkdir()
        (stage / "tracks" / "x.csv").write_text("x\n")
        (stage / "result.json").write_text("{}\n")
        assert not out.exists()  # nothing at the destination until the block ends
    assert _tree(out) == {"result.json": b"{}\n", "tracks/x.csv": b"x\n"}
    assert [p.name for p in out.parent.iterdir()] == ["out"]


def test_a_staged_folder_replaces_its_entries_and_keeps_the_rest(tmp_path):
    out = tmp_path / "out"
    (out / "tracks").mkdir(parents=True)
    (out / "tracks" / "old.csv").write_text("old\n")
    (out / "result.json").write_text("old\n")
    (out / "campaign.toml").write_text("an input beside the outputs\n")
    with staged_folder(out, last=("result.json",)) as stage:
        (stage / "tracks").mkdir()
        (stage / "tracks" / "new.csv").write_text("new\n")
        (stage / "result.json").write_text("new\n")
    assert _tree(out) == {"campaign.toml": b"an input beside the outputs\n", "result.json": b"new\n",
                          "tracks/new.csv": b"new\n"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("error", [RuntimeError, ServoscopeError, KeyboardInterrupt])
def test_a_failed_staged_folder_leaves_the_old_one_as_it_was(tmp_path, error):
    out = tmp_path / "out"
    out.mkdir()
    (out / "result.json").write_text("old\n")
    with pytest.raises(error):
        with staged_folder(out, keep=(".cache",), last=("result.json",)) as stage:
            (stage / "result.json").write_text("new\n")
            raise error("failed half-way")
    assert _tree(out) == {"result.json": b"old\n"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("error, kept", [(RuntimeError, False), (ServoscopeError, False), (KeyboardInterrupt, True)])
def test_a_failed_new_folder_is_removed_with_its_parents_but_ctrl_c_keeps_the_cache(tmp_path, error, kept):
    out = tmp_path / "new" / "out"
    with pytest.raises(error):
        with staged_folder(out, keep=(".cache",)) as stage:
            (out / ".cache").mkdir(parents=True)  # a cache written in place during the run
            (out / ".cache" / "k.json").write_text("{}")
            (stage / "report.html").write_text("half")
            raise error("failed")
    if kept:  # Ctrl-C: the next run resumes from the tracks already made; nothing that looks like output
        assert _tree(out) == {".cache/k.json": b"{}"} and [p.name for p in out.parent.iterdir()] == ["out"]
    else:
        assert list(tmp_path.iterdir()) == []


def test_a_staged_folder_onto_a_file_is_bad_input(tmp_path):
    (tmp_path / "out").write_text("a file")
    with pytest.raises(ServoscopeError, match="not a folder"):
        with staged_folder(tmp_path / "out"):
            pass


def test_staged_files_are_written_together_or_not_at_all(tmp_path):
    csv, video = tmp_path / "t.csv", tmp_path / "t.mp4"
    csv.write_text("old\n")
    with pytest.raises(RuntimeError):
        with staged_files(csv, video) as (tmp_csv, tmp_video):
            tmp_csv.write_text("new\n")
            tmp_video.write_bytes(b"half a vid")
            raise RuntimeError("the overlay failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"] and csv.read_text() == "old\n"
    with staged_files(csv, None) as (tmp_csv, none):
        assert none is None
        tmp_csv.write_text("new\n")
    assert csv.read_text() == "new\n"
