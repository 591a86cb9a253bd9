"""Output paths are checked before the work: every command that writes refuses a folder it
cannot create or a file it cannot write with one line and exit status 2, before it runs; a
write that fails after the checks is one line and exit status 1, never a traceback.
(`bench`, `replay` and `trials` have their own tests in test_bench_errors.py, test_replay.py
and test_trials.py.)"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import has
from picopit.outputs import OutputError, check_dir, check_file

pytestmark = pytest.mark.skipif(not has("Plant"), reason="dynamics::plant not bound yet")


def picopit_cmd() -> list:
    script = Path(sys.executable).parent / "picopit"
    return [str(script)] if script.exists() else [sys.executable, "-m", "picopit.cli"]


def run_cli(*args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(picopit_cmd() + list(args), cwd=cwd, capture_output=True, text=True, timeout=timeout)


def one_line(proc: subprocess.CompletedProcess) -> str:
    err = proc.stderr.strip()
    assert "Traceback" not in err, err
    assert len(err.splitlines()) == 1, err
    return err


# Each command with the cheapest arguments that do real work, and where its output goes.
COMMANDS = {
    "simulate": (["simulate", "--duration", "2", "--no-progress"], "--out"),
    "datagen": (["datagen", "--episodes", "3", "--no-progress"], "--out"),
    "scenarios": (["scenarios", "--n", "6", "--keep", "3", "--no-progress", "--no-figures"], "--out"),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("bad", ["/proc/picopit-x", "/dev/full"])
def test_an_unwritable_out_folder_is_refused_before_the_work(tmp_path, command, bad):
    args, opt = COMMANDS[command]
    t0 = time.monotonic()
    proc = run_cli(*args, opt, bad, cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    err = one_line(proc)
    assert opt in err and bad in err, err
    assert time.monotonic() - t0 < 30, "refused before the work"


def test_a_write_that_fails_after_the_checks_is_one_line_and_status_1(tmp_path):
    # The folder is writable, but the CSV's name is taken by a folder.
    out = tmp_path / "sim"
    (out / "trajectory.csv").mkdir(parents=True)
    proc = run_cli("simulate", "--duration", "1", "--no-progress", "--out", str(out), cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    err = one_line(proc)
    assert "trajectory.csv" in err, err


def test_check_dir_and_check_file(tmp_path):
    assert check_dir(tmp_path / "a" / "b", "--out").is_dir()
    f = check_file(tmp_path / "c" / "d.json", "--json")
    assert f.parent.is_dir() and not f.exists(), "a probe leaves no file behind"
    (tmp_path / "keep.json").write_text("x")
    check_file(tmp_path / "keep.json", "--json")
    assert (tmp_path / "keep.json").read_text() == "x", "an existing file is not truncated"
    for path, check, needle in ((tmp_path / "keep.json", check_dir, "not a folder"),
                                (tmp_path, check_file, "is a folder"),
                                (Path("/dev/null"), check_file, "not a regular file"),
                                (Path("/proc/picopit-x/y"), check_file, "cannot create the folder")):
        with pytest.raises(OutputError, match=needle):
            check(path, "--opt")
