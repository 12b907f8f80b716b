"""Writing output files whole or not at all."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from .results import jsonable

__all__ = ["write_text_atomic", "write_json_atomic"]


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write a file through a temporary name and rename it into place.

    A reader (or a user after a crash) sees the old file or the new one,
    never half of one.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def write_json_atomic(path: str | Path, data: Any) -> None:
    write_text_atomic(path, json.dumps(jsonable(data), indent=2, allow_nan=False) + "\n")
