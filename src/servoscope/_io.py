"""Writing output files and folders whole or not at all: servoscope's one atomic writer.

Every file servoscope writes (result.json, report.html, figures, CSV tables,
cached tracks, overlay videos) is written under a temporary name beside its
destination and renamed into place when whole. A reader, or a user after a
crash or Ctrl-C, sees the old file or the new one, never half of one; a
failed write leaves no temporary file behind.

A command's output folder (``identify --out``, ``simulate``, ``demo``) is
built the same way, one level up (:func:`staged_folder`): in a temporary
folder beside it, moved into place when the command has written everything;
whatever fails (bad input found late, an internal error, Ctrl-C) removes the
temporary folder and leaves the previous output as it was. A command's
several output files (``track --out --overlay``) are committed together
(:func:`staged_files`).
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager, suppress
from pathlib import Path
from typing import Any

from .errors import ServoscopeError
from .results import jsonable

__all__ = ["atomic_path", "staged_files", "staged_folder", "write_bytes_atomic", "write_json_atomic",
           "write_text_atomic"]


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path``, renamed onto it when the block ends without an error.

    For writers that want a path of their own (a codec, ``numpy.savez``,
    ``Figure.savefig``): the temporary name keeps the destination's suffix,
    so that writers choosing a format by it choose the same one.

    Parameters
    ----------
    path : str or path-like
        The destination; its folder must exist.

    Yields
    ------
    Path
        Where to write; on an error it is deleted and the error raised.
    """
    path = Path(path)
    # The process id keeps two processes writing the same file (two workers
    # caching one video) from writing into each other's temporary file.
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        yield tmp
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write bytes to ``path`` whole or not at all (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write UTF-8 text to ``path`` whole or not at all (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: str | Path, data: Any) -> None:
    """Write ``data`` as indented JSON (NaN refused; numpy types made plain by :func:`servoscope.results.jsonable`)."""
    write_text_atomic(path, json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")


@contextmanager
def staged_files(*paths: str | Path | None) -> Iterator[tuple[Path | None, ...]]:
    """Temporary paths beside several destinations, all renamed into place when the block ends without an error.

    A command's output files (a track's CSV and its overlay video) are written
    together or not at all: an error while writing any of them leaves every
    destination as it was. Each is :func:`atomic_path`'s; None stays None (an
    output not asked for). The renames happen last to first, once every file
    is whole.
    """
    with ExitStack() as stack:
        yield tuple(None if p is None else stack.enter_context(atomic_path(p)) for p in paths)


@contextmanager
def staged_folder(path: str | Path, *, keep: tuple[str, ...] = (), last: tuple[str, ...] = ()) -> Iterator[Path]:
    """A folder built aside (``PATH.tmp-XXXXXXXX``, beside ``path``) and moved onto ``path`` when the block ends.

    The block writes everything into the yielded folder. Without an error, it
    is moved into place: renamed to ``path`` in one step when ``path`` does not
    exist; into an existing folder, each entry it holds replaces its namesake
    (a file, or a whole sub-folder such as ``tracks/``) and whatever else the
    folder holds stays (the user's files, a campaign's inputs beside its
    outputs, a cache). The entries named in ``last`` (the file whose presence
    says the output is finished, ``result.json``) are taken out of the old
    folder first and put in last, so that a folder with one is whole.

    On any error (a bad input found late, an internal error, Ctrl-C) the
    temporary folder is removed and the error raised; an existing ``path`` is
    left as it was. A ``path`` that did not exist before the block is removed
    too, with any folders made for it, when it holds nothing but the ``keep``
    entries written there directly (``identify``'s track cache, ``.cache``):
    no folder is left behind that looks like output. After Ctrl-C (the user
    stopping a long run to resume it) the ``keep`` entries stay, so that the
    next run finds the tracks already made.

    Parameters
    ----------
    path : str or path-like
        The output folder; its parent is created when missing.
    keep : tuple of str
        Names written into ``path`` itself during the block, kept on Ctrl-C.
    last : tuple of str
        Names moved into place last.

    Yields
    ------
    Path
        The temporary folder to write into (same filesystem as ``path``).

    Raises
    ------
    ServoscopeError
        ``path`` exists and is not a folder, or the folders cannot be made or moved.
    """
    path = Path(os.path.abspath(path))
    if path.exists() and not path.is_dir():
        raise ServoscopeError(f"{path}: exists and is not a folder")
    existed = path.exists()
    made = _missing_parents(path)
    stage = _make_stage(path)
    try:
        yield stage
        _move_into_place(stage, path, last)
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        if not existed:
            _remove_new_output(path, made, keep, interrupted=isinstance(exc, KeyboardInterrupt))
        raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _missing_parents(path: Path) -> list[Path]:
    """``path`` and those of its parents that do not exist yet, deepest first."""
    missing = []
    for folder in (path, *path.parents):
        if folder.exists():
            break
        missing.append(folder)
    return missing


def _make_stage(path: Path) -> Path:
    """A new, empty folder ``PATH.tmp-XXXXXXXX`` beside ``path`` (mkdir: the user's umask applies)."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        while True:
            stage = path.with_name(f"{path.name}.tmp-{secrets.token_hex(4)}")
            try:
                stage.mkdir()
                return stage
            except FileExistsError:
                continue
    except OSError as exc:
        raise ServoscopeError(f"{path}: cannot write there ({exc.strerror or exc})") from None


def _move_into_place(stage: Path, path: Path, last: tuple[str, ...]) -> None:
    """Move the finished ``stage`` onto ``path``: renamed whole, or entry by entry into an existing folder."""
    try:
        if not path.exists():
            os.rename(stage, path)
            return
        names = sorted(os.listdir(stage), key=lambda name: (name in last, name))
        trash = Path(os.path.join(path, f".{path.name}.replaced-{secrets.token_hex(4)}"))
        trash.mkdir()
    except OSError as exc:
        raise ServoscopeError(f"{path}: cannot move the new output into place ({exc.strerror or exc})") from None
    moved: list[tuple[str, bool]] = []  # (name, whether an old entry was set aside)
    try:
        for name in [n for n in last if n in names]:  # the old 'finished' mark goes first
            if os.path.lexists(path / name):
                os.rename(path / name, trash / name)
        for name in names:
            old = os.path.lexists(path / name) and not os.path.lexists(trash / name)
            if old:
                os.rename(path / name, trash / name)
            moved.append((name, old or os.path.lexists(trash / name)))
            os.rename(stage / name, path / name)
    except OSError as exc:
        _put_back(stage, path, trash, moved, last)
        with suppress(OSError):
            trash.rmdir()  # only when everything went back: what did not stays there, not deleted
        raise ServoscopeError(f"{path}: cannot move the new output into place ({exc.strerror or exc}); the "
                              "previous output is put back as far as it could be") from None
    shutil.rmtree(trash, ignore_errors=True)


def _put_back(stage: Path, path: Path, trash: Path, moved: list[tuple[str, bool]], last: tuple[str, ...]) -> None:
    """Undo a part-done :func:`_move_into_place` as far as the filesystem lets: the old entries back in place."""
    for name, had_old in reversed(moved):
        with suppress(OSError):
            if not os.path.lexists(stage / name) and os.path.lexists(path / name):
                os.rename(path / name, stage / name)
            if had_old:
                os.rename(trash / name, path / name)
    for name in last:
        with suppress(OSError):
            if os.path.lexists(trash / name) and not os.path.lexists(path / name):
                os.rename(trash / name, path / name)


def _remove_new_output(path: Path, made: list[Path], keep: tuple[str, ...], *, interrupted: bool) -> None:
    """After a failure: remove the output folder a run made (and the parents made for it), unless it holds more."""
    if os.path.islink(path) or path.exists() and not path.is_dir():
        return
    if path.exists():
        held = set(os.listdir(path))
        if not held <= set(keep) or (interrupted and held):
            return  # someone else's files, or a cache the next run resumes from
        shutil.rmtree(path, ignore_errors=True)
    for folder in made[1:]:
        try:
            folder.rmdir()  # only when empty: a folder someone else wrote into since stays
        except OSError:
            break
