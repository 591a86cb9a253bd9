"""Shared helpers for the cross-language tests (run with ./scripts/test.sh)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import picopit


def replace_field(toml_text: str, table: str, key: str, new_line: str | None) -> str:
    """Replace (or, with None, delete) the line `key = ...` inside `[table]` of TOML text."""
    out, current = [], None
    for line in toml_text.splitlines():
        stripped = line.strip()
        m = re.match(r"^\[([^\]]+)\]$", stripped)
        if m:
            current = m.group(1).strip()
        if current == table and re.match(rf"^{re.escape(key)}\s*=", stripped):
            if new_line is not None:
                out.append(new_line)
            continue
        out.append(line)
    return "\n".join(out) + "\n"


@pytest.fixture
def param_file(tmp_path: Path):
    """Write a variant of a built-in parameter set to a temp file and return its path."""

    def make(table: str, key: str, new_line: str | None, base: str = "full_size") -> str:
        text = replace_field(picopit.load_params(base), table, key, new_line)
        path = tmp_path / f"{base}-{table}-{key}.toml"
        path.write_text(text)
        return str(path)

    return make


def has(name: str) -> bool:
    """Whether the extension binds `name` yet (the plant and models land with their APIs)."""
    return hasattr(picopit._core, name)
