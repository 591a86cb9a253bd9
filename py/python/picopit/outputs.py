"""Output paths checked before the work: a command that would write to a folder it cannot
create, or to a file it cannot write, says so in one line (exit status 2) instead of running
for minutes and then failing with a traceback.

``check_dir`` creates the folder and proves it writable with a probe file it removes again;
``check_file`` refuses an existing path that is a folder or not a regular file (a device
such as ``/dev/full``, a FIFO), creates the parent folder and opens the file for appending
(nothing is truncated; a file the probe created is removed again).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Optional, Union

PathLike = Union[str, "os.PathLike[str]"]


class OutputError(ValueError):
    """An output path that cannot be written; the message names the option and the path."""


def _why(e: OSError) -> str:
    return e.strerror or str(e)


def check_dir(path: PathLike, option: str) -> Path:
    """Create the folder ``path`` (and its parents) and check that files can be written in
    it; returns it. Raises :class:`OutputError` naming ``option``."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{option} {p}: exists and is not a folder")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{option} {p}: cannot create the folder: {_why(e)}") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=".picopit-probe-", dir=p)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise OutputError(f"{option} {p}: cannot write in the folder: {_why(e)}") from None
    return p


def check_file(path: PathLike, option: str) -> Path:
    """Check that the file ``path`` can be written (creating its parent folder); returns it.
    Raises :class:`OutputError` naming ``option``."""
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{option} {p}: is a folder, not a file")
    if p.exists() and not p.is_file():
        raise OutputError(f"{option} {p}: not a regular file")
    existed = p.exists()
    parent = p.parent
    if not parent.is_dir():
        if parent.exists():
            raise OutputError(f"{option} {p}: {parent} is not a folder")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise OutputError(f"{option} {p}: cannot create the folder {parent}: {_why(e)}") from None
    try:
        with open(p, "ab"):
            pass
    except OSError as e:
        raise OutputError(f"{option} {p}: cannot write: {_why(e)}") from None
    if not existed:
        try:
            p.unlink()
        except OSError:
            pass
    return p


def check_optional_file(path: Optional[PathLike], option: str) -> Optional[Path]:
    return None if path is None else check_file(path, option)
