"""`picopit bench` when things are wrong: model files that are missing, corrupt, absurd (finite
weights whose network overflows) or of another parameter set stop the run before it starts
(exit 2); episodes that error on the way make the exit status 1 with their count; output paths
are checked before the work; an unreachable Ray head is an error within seconds; NaN never
stands in the per-episode table as a number."""

from __future__ import annotations

import json
import math
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import has

pytestmark = pytest.mark.skipif(not has("run_episode"), reason="sim::episode not bound yet")

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "models"


def picopit_cmd() -> list:
    script = Path(sys.executable).parent / "picopit"
    return [str(script)] if script.exists() else [sys.executable, "-m", "picopit.cli"]


def bench(*args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(picopit_cmd() + ["bench", "--no-progress", "--no-figures", "--workers", "1"] + list(args),
                          cwd=cwd, capture_output=True, text=True, timeout=timeout)


def one_line_error(proc: subprocess.CompletedProcess) -> str:
    err = proc.stderr.strip()
    assert "Traceback" not in err, err
    assert len(err.splitlines()) == 1, err
    return err


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> Path:
    """Two full-size scenes of the dataset, the second on μ = 1.1 (outside the shipped
    surrogates' mu_range, so its PicoPINN episode errors)."""
    lines = [ln for ln in (REPO / "data" / "scenarios.jsonl").read_text().splitlines()
             if json.loads(ln)["params"] == "full_size"][:2]
    second = json.loads(lines[1])
    second.update(mu=1.1, adhesion="high")
    path = tmp_path_factory.mktemp("scenes") / "two.jsonl"
    path.write_text(lines[0] + "\n" + json.dumps(second) + "\n")
    return path


def models_with(tmp: Path, picopinn: "bytes | Path") -> Path:
    """A models folder whose full_size/picopinn.safetensors is ``picopinn``."""
    d = tmp / "models" / "full_size"
    d.mkdir(parents=True)
    target = d / "picopinn.safetensors"
    if isinstance(picopinn, Path):
        shutil.copy(picopinn, target)
    else:
        target.write_bytes(picopinn)
    return tmp / "models"


def overflowing_model(path: Path) -> None:
    """The shipped full-size PicoPINN with every free parameter set to 1e308: finite, so it
    passes every check of the file itself, but its network overflows to inf/NaN."""
    np = pytest.importorskip("numpy")
    st = pytest.importorskip("safetensors.numpy")
    from safetensors import safe_open

    src = MODELS / "full_size" / "picopinn.safetensors"
    with safe_open(str(src), "np") as f:
        meta = f.metadata()
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    tensors["theta"] = np.full_like(tensors["theta"], 1e308)
    st.save_file(tensors, str(path), metadata=meta)


@pytest.mark.parametrize("kind", ["corrupt", "overflowing", "half_scale", "missing"])
def test_a_bad_model_file_stops_the_run_before_it_starts(tmp_path, scenes, kind):
    if kind == "corrupt":
        models = models_with(tmp_path, b"\x00" * 64)
        needle = "not a valid safetensors file"
    elif kind == "overflowing":
        overflowing_model(tmp_path / "huge.safetensors")
        models = models_with(tmp_path, tmp_path / "huge.safetensors")
        needle = "finite outputs"
    elif kind == "half_scale":
        models = models_with(tmp_path, MODELS / "half_scale" / "picopinn.safetensors")
        needle = "trained on param_set 'half_scale'"
    else:
        models = tmp_path / "models"
        (models / "full_size").mkdir(parents=True)
        needle = "no such file"
    t0 = time.monotonic()
    proc = bench("--scenarios", str(scenes), "--full", "--models", str(models), "--configs", "4dof,picopinn",
                 "--out", "run", cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    err = one_line_error(proc)
    assert "picopinn" in err and "full_size/picopinn.safetensors" in err and needle in err, err
    assert not (tmp_path / "run" / "summary.json").exists(), "nothing ran"
    assert time.monotonic() - t0 < 60


def test_errored_episodes_make_the_exit_status_1_with_their_count(tmp_path, scenes):
    proc = bench("--scenarios", str(scenes), "--full", "--models", str(MODELS), "--configs", "picopinn",
                 "--clock", "simulated", "--out", "run", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "1 of 2 episodes could not be run" in proc.stderr and "mu_range" in proc.stderr, proc.stderr
    doc = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert doc["configs"]["picopinn"]["errors"] == 1
    assert doc["configs"]["picopinn"]["fail_error"] == 50.0


@pytest.mark.parametrize("opt,value", [("--out", "/proc/picopit-x"), ("--json", "/dev/full"),
                                       ("--json", "/proc/picopit-x/summary.json")])
def test_unwritable_outputs_are_refused_before_any_episode(tmp_path, scenes, opt, value):
    t0 = time.monotonic()
    args = ["--scenarios", str(scenes), "--full", "--models", str(MODELS), "--configs", "4dof", opt, value]
    proc = bench(*(args + (["--out", "run"] if opt != "--out" else [])), cwd=tmp_path)
    assert proc.returncode == 2, proc.stderr
    err = one_line_error(proc)
    assert opt in err and value in err, err
    assert not (tmp_path / "run" / "summary.json").exists(), "nothing ran"
    assert time.monotonic() - t0 < 60


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_ray_head_is_an_error_within_seconds(tmp_path, scenes):
    pytest.importorskip("ray")
    port = _free_port()
    proc = bench("--scenarios", str(scenes), "--full", "--models", str(MODELS), "--configs", "4dof", "--ray-address",
                 f"127.0.0.1:{port}", "--out", "run", cwd=tmp_path, timeout=120)
    assert proc.returncode == 2, proc.stderr
    err = one_line_error(proc)
    assert "--ray-address" in err and f"127.0.0.1:{port}" in err, err


def test_ray_addresses_name_their_endpoint():
    from picopit.bench_checks import ray_endpoint

    assert ray_endpoint("local") is None and ray_endpoint("auto") is None
    assert ray_endpoint("10.0.0.5:6380") == ("10.0.0.5", 6380)
    assert ray_endpoint("head") == ("head", 6379)
    assert ray_endpoint("ray://head:10002") == ("head", 10002)
    assert ray_endpoint("ray://head") == ("head", 10001)
    assert ray_endpoint("[::1]:6379") == ("::1", 6379)


def test_no_nan_reaches_the_episode_table():
    from picopit import bench as b

    meta = {0: {"id": "s", "category": "curved", "road": "curved", "adhesion": "high", "params": "full_size",
                "mu": 0.9, "target_speed": 15.0}}
    row = {"config": "4dof", "index": 0, "success": False, "cause": "secondary_collision",
           "terminal_heading_error": math.nan, "min_margin": -math.inf, "impact_speed": 2.5}
    (d,) = b.episode_table([row], meta)
    assert d["terminal_heading_error"] is None and d["min_margin"] is None
    assert d["impact_speed"] == 2.5
