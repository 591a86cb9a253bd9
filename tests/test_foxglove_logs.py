"""Recordings that Foxglove opens: every message of a pit-vehicle / pit-controller recording
and of the benchmark's cases.mcap is valid against the schema its channel names, the Foxglove
topics carry the Foxglove SDK's published schemas, and what a viewer draws is there (the
vehicles, the road, the obstacles, the contact-force arrow). ``picopit replay`` still reads
the recordings. Helper: tests/foxglove_check.py."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("google.protobuf")
pytest.importorskip("jsonschema")
pytest.importorskip("mcap")
pytest.importorskip("foxglove")

from foxglove_check import check_recording  # noqa: E402

from picopit import _core, cases_mcap  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RELEASE = ROOT / "target" / "release"
TRIALS = ROOT / "data" / "trials" / "half_scale.jsonl"
SCENARIOS = ROOT / "data" / "scenarios.jsonl"
MODELS = ROOT / "models"


def _arrows(scenes) -> int:
    return sum(1 for s in scenes for e in s.entities if e.id == "contact" and len(e.arrows) > 0)


@pytest.mark.skipif(not (RELEASE / "pit-vehicle").exists() or not (RELEASE / "pit-controller").exists(),
                    reason="target/release/pit-vehicle or pit-controller not built "
                           "(./scripts/setup.sh --full or cargo build --release -p picopit-vehicle-io --bins)")
def test_vehicle_and_controller_recordings_are_valid_foxglove_logs(tmp_path):
    prefix = f"picopit-pytest-fox-{os.getpid()}"
    common = ["--scenario", str(TRIALS), "--id", "R4", "--prefix", prefix, "--connect-timeout", "60"]
    vm, cm = tmp_path / "vehicle.mcap", tmp_path / "controller.mcap"
    v = subprocess.Popen([str(RELEASE / "pit-vehicle"), *common, "--clock", "simulated", "--record", str(vm)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    c = subprocess.Popen([str(RELEASE / "pit-controller"), *common, "--clock", "vehicle",
                          "--controller-config", str(ROOT / "configs" / "controller_half_scale.toml"),
                          "--model", "4dof", "--record", str(cm)],
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        assert v.wait(timeout=300) == 0, v.stderr.read()
        assert c.wait(timeout=60) == 0, c.stderr.read()
    finally:
        for p in (v, c):
            if p.poll() is None:
                p.kill()
                p.wait()
    for path in (vm, cm):
        rec = check_recording(path)
        n = rec.counts["/state"]
        assert n > 50, rec.counts
        assert rec.schemas["/scene"] == "foxglove.SceneUpdate"
        assert rec.schemas["/tf"] == "foxglove.FrameTransforms"
        assert rec.schemas["/bullet/pose"] == rec.schemas["/target/pose"] == "foxglove.PoseInFrame"
        for t in ("/scene", "/tf", "/bullet/pose", "/target/pose", "/bullet/state", "/target/state", "/contact"):
            assert rec.counts[t] == n, (path.name, t)
        assert rec.counts["/road"] == 1
        scenes = rec.scenes["/scene"]
        assert {e.id for e in scenes[0].entities} == {"bullet", "target", "contact", "road"}
        pushes = sum(1 for m in rec.json["/contact"] if m["normal_force"] > 0.0)
        assert pushes > 0 and _arrows(scenes) == pushes, (path.name, pushes, _arrows(scenes))
        # Plot-ready: the named speed is the state's.
        s, b = rec.json["/state"][-1], rec.json["/bullet/state"][-1]
        assert b["speed"] == pytest.approx(float(np.hypot(s["bullet"][3], s["bullet"][4])))

    # picopit replay reads the new layout (JSON topics only; the road from /road).
    png = tmp_path / "replay.png"
    r = subprocess.run([sys.executable, "-m", "picopit", "replay", str(vm), "--out", str(png)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert png.stat().st_size > 0 and "did not decode" not in r.stdout
    from picopit.replay import read_recording

    assert len(read_recording(vm).road()) == 3


def _recorded_case(want_obstacles: bool):
    """A recorded 4-DOF episode of the dataset with a contact (and obstacles when asked)."""
    scenarios = _core.load_scenarios(str(SCENARIOS))
    from picopit.bench import BenchConfig

    cfg = BenchConfig(scenarios=SCENARIOS, models=MODELS, configs=("4dof",))
    text = cfg.episode_config("4dof")
    for sc in scenarios:
        if want_obstacles != bool(sc.get("obstacles")):
            continue
        case = _core.run_episode(json.dumps(sc), text, 0, record=True, models_dir=str(MODELS.resolve()))
        tr = np.asarray(case["trajectory"])
        fn = tr[:, list(_core.trajectory_columns()).index("contact_fn")]
        if (fn > 0).any():
            return case, _core.validate_scenario_line(json.dumps(sc)), int((fn > 0).sum())
    pytest.skip("no scene with a contact")


def test_bench_cases_mcap_is_a_valid_foxglove_log(tmp_path):
    cases, scenes, pushes = {}, {}, {}
    for kind, obstacles in (("success", False), ("failure", True)):
        cases[kind], scenes[kind], pushes[kind] = _recorded_case(obstacles)
    path = tmp_path / "cases.mcap"
    assert cases_mcap.write_mcap(cases, scenes, path) is None
    rec = check_recording(path)
    assert set(rec.counts) == set(cases_mcap.topics(list(cases)))
    for kind, case in cases.items():
        steps = len(case["trajectory"])
        for t in ("step", "scene", "tf", "bullet/pose", "target/pose"):
            assert rec.counts[f"/{kind}/{t}"] == steps, (kind, t)
        scene = rec.scenes[f"/{kind}/scene"]
        ids = {e.id for e in scene[0].entities}
        n_ob = len(scenes[kind].get("obstacles", []))
        assert ids == {"bullet", "target", "contact", "road"} | {f"obstacle/{i}" for i in range(n_ob)}
        road = next(e for e in scene[0].entities if e.id == "road")
        assert len(road.lines) == 2 + scenes[kind]["road"]["lanes"] + 1
        # An arrow in every step with a contact force whose footprints overlapped at least once.
        assert 0 < _arrows(scene) <= pushes[kind], (kind, _arrows(scene), pushes[kind])
        steps_json = rec.json[f"/{kind}/step"]
        assert {"speed", "psi"} <= set(steps_json[0]["target"])
