"""`picopit simulate` end to end, and the CLI's handling of bad input."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import picopit
from conftest import has, replace_field

pytestmark = pytest.mark.skipif(not has("Plant"), reason="dynamics::plant not bound yet")


def picopit_cmd() -> list:
    """The installed console script next to this interpreter, else `python -m picopit.cli`."""
    script = Path(sys.executable).parent / "picopit"
    return [str(script)] if script.exists() else [sys.executable, "-m", "picopit.cli"]


def run_cli(*args: str, cwd: Path):
    return subprocess.run(picopit_cmd() + list(args), cwd=cwd, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sim")
    proc = run_cli("simulate", "--out", "tmp", "--no-progress", cwd=tmp)
    return proc, tmp / "tmp"


def test_default_simulate_writes_csv_png_and_spins_the_target(default_run):
    proc, out = default_run
    assert proc.returncode == 0, proc.stderr
    csv_path, png_path, json_path = out / "trajectory.csv", out / "simulate.png", out / "summary.json"
    for p in (csv_path, png_path, json_path):
        assert p.is_file() and p.stat().st_size > 0, p
    assert png_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(csv_path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) > 100
    yaw = np.array([float(r["target_yaw"]) for r in rows])
    fn = np.array([float(r["contact_Fn"]) for r in rows])
    assert abs(math.degrees(yaw[-1] - yaw[0])) > 90.0
    assert fn.max() > 0.0
    summary = json.loads(json_path.read_text())
    assert abs(summary["summary"]["target_yaw_change_deg"]) > 90.0
    assert summary["config"]["seed"] == 0
    # The one-line summary names the numbers and where the files went.
    assert "peak contact force" in proc.stdout and "target yaw change" in proc.stdout
    assert str(csv_path.relative_to(out.parent)) in proc.stdout or "trajectory.csv" in proc.stdout


def test_simulate_is_deterministic():
    from picopit.simulate import SimulateConfig, run

    a = run(SimulateConfig(duration=4.0), progress=False).data
    b = run(SimulateConfig(duration=4.0), progress=False).data
    for k in a:
        if k == "phase":
            assert list(a[k]) == list(b[k])
        else:
            assert np.array_equal(a[k], b[k], equal_nan=True), k


def test_seed_and_jitter_change_the_initial_conditions():
    from picopit.simulate import SimulateConfig, run

    base = run(SimulateConfig(duration=0.1, jitter=1.0, seed=1), progress=False).data
    again = run(SimulateConfig(duration=0.1, jitter=1.0, seed=1), progress=False).data
    other = run(SimulateConfig(duration=0.1, jitter=1.0, seed=2), progress=False).data
    assert base["target_Y"][0] == again["target_Y"][0]
    assert base["target_Y"][0] != other["target_Y"][0]


def test_toml_config_is_read_and_options_override_it(tmp_path):
    cfg = tmp_path / "run.toml"
    cfg.write_text('[simulate]\nparams = "half_scale"\ntarget_speed = 8\nspeed_diff = 1.0\n'
                   "lateral_offset = -2.0\nduration = 1.0\n")
    proc = run_cli("simulate", "--config", str(cfg), "--duration", "0.5", "--out", "o", "--no-progress",
                   cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["config"]["params"] == "half_scale"
    assert summary["config"]["target_speed"] == 8.0
    assert summary["config"]["duration"] == 0.5


@pytest.mark.parametrize(
    "args, field",
    [
        (["--target-speed", "-3"], "target_speed"),
        (["--speed-diff", "nan"], "speed_diff"),
        (["--mu", "0"], "mu"),
        (["--duration", "-1"], "duration"),
        (["--lateral-offset", "0"], "lateral_offset"),
        (["--record-hz", "33"], "record_hz"),
        (["--seed", "-4"], "seed"),
        (["--params", "monster_truck"], "params"),
        (["--target-speed", "fast"], "--target-speed"),
    ],
)
def test_bad_options_exit_2_naming_the_field(tmp_path, args, field):
    proc = run_cli("simulate", "--out", "o", "--no-progress", *args, cwd=tmp_path)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert field in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o").exists()


def test_bad_param_file_exits_2_naming_the_field(tmp_path):
    path = tmp_path / "heavy.toml"
    path.write_text(replace_field(picopit.load_params("full_size"), "target", "mass", "mass = -1.0"))
    proc = run_cli("simulate", "--params", str(path), "--no-progress", "--out", "o", cwd=tmp_path)
    assert proc.returncode == 2
    assert "target.mass" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    "text, needle",
    [
        ("[simulate\ntarget_speed = 3\n", "not valid TOML"),
        ("target_sped = 3.0\n", "target_sped"),
        ('target_speed = "fast"\n', "target_speed"),
        ("[simulate]\nmu = -1.0\n", "mu"),
    ],
)
def test_bad_config_file_exits_2(tmp_path, text, needle):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(text)
    proc = run_cli("simulate", "--config", str(cfg), "--no-progress", "--out", "o", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    assert needle in proc.stderr and "Traceback" not in proc.stderr


def test_missing_config_file_exits_2(tmp_path):
    proc = run_cli("simulate", "--config", "nope.toml", "--no-progress", cwd=tmp_path)
    assert proc.returncode == 2 and "nope.toml" in proc.stderr and "Traceback" not in proc.stderr


def test_params_subcommand_lists_and_prints(tmp_path):
    proc = run_cli("params", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stdout.split() == ["full_size", "half_scale"]
    proc = run_cli("params", "half_scale", cwd=tmp_path)
    assert proc.returncode == 0 and "[bullet]" in proc.stdout


@pytest.mark.parametrize("argv", [["datagen", "--out", "x"], ["train", "--data", "x"], ["compress", "x"],
                                  ["eval-surrogates", "--data", "x", "--pinn", "y", "--picopinn", "z"]])
def test_a_command_whose_extra_is_missing_names_the_package_and_the_set_up(monkeypatch, capsys, argv):
    """The main job's set-up has no torch: the commands that need it say so in one line (exit
    status 2), and the others, bench among them, still parse."""
    from picopit import cli

    monkeypatch.setitem(sys.modules, "torch", None)  # `import torch` raises ModuleNotFoundError
    for mod in ("picopit.train", "picopit.compress", "picopit.surrogate_nn", "picopit.eval_surrogates",
                "picopit.datagen", "picopit.physics"):
        monkeypatch.delitem(sys.modules, mod, raising=False)
    assert cli.build_parser().parse_args(["bench", "--limit", "1"]).command == "bench"
    rc = cli.main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "needs the Python package 'torch'" in err and "./scripts/setup.sh --full" in err
    assert "Traceback" not in err
