"""servoscope's one atomic writer: a file is replaced whole or left as it was."""

from __future__ import annotations

import json

import pytest

from servoscope._io import atomic_path, write_bytes_atomic, write_json_atomic, write_text_atomic


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
