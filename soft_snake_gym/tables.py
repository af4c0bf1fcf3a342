"""Result tables that survive an interruption: CSV files written a row at a time, read back to resume.

Every long job that produces rows (a sweep's cells, a robustness study's cells, a training run's
evaluations) appends each one as soon as it exists, flushed to disk, and reads the finished ones
back when it starts again. A job killed in the middle of a write leaves a torn last line; it is
not a row, and it is cut before the next row is appended (else that row would be glued to it).
"""

from __future__ import annotations

import contextlib
import csv
import os
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["appending", "read_rows"]


def _cut_torn_line(path: Path) -> None:
    """Truncate ``path`` after its last complete line (a row ends with a newline)."""
    size = path.stat().st_size
    if size == 0:
        return
    with path.open("rb+") as f:
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return
        f.seek(0)
        data = f.read()
        f.truncate(data.rfind(b"\n") + 1)


def read_rows(path: str | Path) -> list[dict[str, str]]:
    """The complete rows of the CSV at ``path`` (none if it does not exist), as text.

    A torn last line (no newline: the writer was killed mid-row) is left out.
    """
    path = Path(path)
    if not path.is_file():
        return []
    with path.open(newline="") as f:
        text = f.read()
    if not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return [r for r in csv.DictReader(text.splitlines(keepends=True)) if None not in r.values()]


@contextlib.contextmanager
def appending(path: str | Path, fields: list[str]) -> Iterator[Callable[[dict[str, Any]], None]]:
    """Append rows to the CSV at ``path``: yields ``write(row)``, which writes and syncs one row.

    A new (or empty) file gets the header ``fields``; an existing one keeps its own rows and loses
    only a torn last line. ``row`` keys outside ``fields`` are ignored, missing ones are empty.
    """
    path = Path(path)
    if path.is_file():
        _cut_torn_line(path)
    new = not path.is_file() or path.stat().st_size == 0
    with path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=fields)
        if new:
            writer.writeheader()
            f.flush()

        def write(row: dict[str, Any]) -> None:
            writer.writerow({k: row.get(k, "") for k in fields})
            f.flush()
            os.fsync(f.fileno())

        yield write
