"""Where a written artefact came from: the source tree's commit."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Optional, Sequence


def git_commit(cwd: Optional[Path] = None, ignore: Sequence[str] = ()) -> str:
    """HEAD of the git tree holding ``cwd`` (default: this package), with ``-dirty`` when a
    tracked file has uncommitted changes outside the top-level folders ``ignore``;
    ``unknown`` outside a git tree or without git."""
    where = cwd or Path(__file__).parent
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=where, timeout=10)
        if out.returncode != 0:
            return "unknown"
        spec = [":(top)"] + [f":(top,exclude){p}" for p in ignore]
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", *spec],
                               capture_output=True, text=True, cwd=where, timeout=10).stdout.strip()
        return out.stdout.strip() + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"
