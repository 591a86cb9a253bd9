"""`picopit bench` end to end on a few scenes, its option checks, the stratified scene set,
the episode binding, and the same work on a local Ray instance (when ray is installed)."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import picopit
from conftest import has

pytestmark = pytest.mark.skipif(not has("run_episode"), reason="sim::episode not bound yet")

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "data" / "scenarios.jsonl"
MODELS = REPO / "models"
PRESETS = ["4dof", "pinn", "picopinn", "picopinn_no_upper"]


def picopit_cmd() -> list:
    script = Path(sys.executable).parent / "picopit"
    return [str(script)] if script.exists() else [sys.executable, "-m", "picopit.cli"]


def run_cli(*args: str, cwd: Path):
    return subprocess.run(picopit_cmd() + ["bench", "--scenarios", str(SCENARIOS), "--models", str(MODELS)]
                          + list(args), cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("bench")
    proc = run_cli("--limit", "3", "--out", "run", "--json", "out/summary.json", "--workers", "2",
                   "--no-progress", cwd=tmp)
    return proc, tmp


def test_bench_writes_the_tables_json_episodes_and_figures(bench_run):
    proc, tmp = bench_run
    assert proc.returncode == 0, proc.stderr
    run = tmp / "run"
    for name in ("summary.md", "summary.csv", "summary.json", "panels.png", "contacts.png"):
        assert (run / name).stat().st_size > 0, name
    doc = json.loads((tmp / "out" / "summary.json").read_text())
    assert doc == json.loads((run / "summary.json").read_text())
    assert list(doc["configs"]) == PRESETS
    for name, s in doc["configs"].items():
        assert s["episodes"] == 3
        assert 0.0 <= s["success_rate"] <= 100.0
        assert 0.0 <= s["success_at_rest_rate"] <= s["success_rate"]
        assert s["ctrl_ms_median"] > 0.0
        for key in ("success_straight", "success_curved", "success_low", "success_mid", "success_high",
                    "heading_error_deg_median", "min_margin_m_median", "boundary_violation_rate",
                    "secondary_collision_rate", "plan_ms_median", "plan_ms_p99", "ctrl_ms_p99", "param_count",
                    "fail_decision_infeasible", "fail_no_termination", "fail_boundary_violation",
                    "fail_secondary_collision", "fail_unsafe_rebound"):
            assert key in s, (name, key)
        causes = sum(s[f"fail_{c}"] for c in ("decision_infeasible", "no_termination", "boundary_violation",
                                              "secondary_collision", "unsafe_rebound", "error"))
        assert causes + s["success_rate"] == pytest.approx(100.0), "every episode has one outcome"
    # The upper layer plans; without it nothing does.
    assert doc["configs"]["picopinn"]["plan_ms_median"] > 0.0
    assert doc["configs"]["picopinn_no_upper"]["plan_ms_median"] is None
    assert doc["configs"]["4dof"]["param_count"] == 0
    assert doc["configs"]["pinn"]["param_count"] > doc["configs"]["picopinn"]["param_count"] > 0
    assert doc["run"]["scenes"] == 3 and len(doc["run"]["scene_ids"]) == 3
    md = (run / "summary.md").read_text()
    assert "| config | episodes | success % | at rest % | straight % | curved %" in md
    assert "Failure causes" in md
    # By the target's speed: every band, each scene in one of them.
    for s in doc["configs"].values():
        assert [b["band"] for b in s["by_speed"]] == ["< 10", "10–15", "15–20", "≥ 20"]
        assert sum(b["episodes"] for b in s["by_speed"]) == s["episodes"]
    assert "| picopinn | ≥ 20 |" in md
    # By the driver: every kind listed, each scene under its own (the three scenes' kinds).
    drivers = {d["id"]: d["driver"]["kind"] for d in map(json.loads, SCENARIOS.read_text().splitlines())}
    kinds = sorted(drivers[i] for i in doc["run"]["scene_ids"])
    for s in doc["configs"].values():
        assert [b["driver"] for b in s["by_driver"]] == ["none", "lane_keep", "brake", "counter_steer"]
        assert sorted(b["driver"] for b in s["by_driver"] for _ in range(b["episodes"])) == kinds
    assert f"| picopinn | {kinds[0]} |" in md
    # By the side of a curve: the touched curved scenes, each under one side.
    for s in doc["configs"].values():
        assert [b["curve_side"] for b in s["by_curve_side"]] == ["inside", "outside"]
    assert "| picopinn | inside |" in md
    # Paired comparison: every pair once, its counts agree with the per-configuration successes.
    assert "Paired comparison" in md
    assert len(doc["paired"]) == len(PRESETS) * (len(PRESETS) - 1) // 2
    for p in doc["paired"].values():
        assert p["scenes"] == 3 and 0.0 <= p["mcnemar_p"] <= 1.0
        assert p["only_a"] + p["both"] == doc["configs"][p["a"]]["successes"]
        assert p["only_b"] + p["both"] == doc["configs"][p["b"]]["successes"]
    with open(run / "summary.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["config"] for r in rows] == PRESETS
    assert "bench: 3 scenes x 4 configurations" in proc.stdout


def test_per_episode_results_agree_with_the_summary(bench_run):
    proc, tmp = bench_run
    assert proc.returncode == 0, proc.stderr
    run = tmp / "run"
    doc = json.loads((run / "summary.json").read_text())
    if (run / "episodes.parquet").exists():
        pq = pytest.importorskip("pyarrow.parquet")
        table = pq.read_table(run / "episodes.parquet").to_pylist()
    else:  # pyarrow missing: the CSV fallback, said so in the notes
        assert any("CSV" in n for n in doc["run"]["notes"])
        with open(run / "episodes.csv") as fh:
            table = [dict(r, success=r["success"] == "True") for r in csv.DictReader(fh)]
    assert len(table) == 12
    for name in PRESETS:
        rows = [r for r in table if r["config"] == name]
        assert len(rows) == 3
        rate = 100.0 * sum(bool(r["success"]) for r in rows) / 3
        assert doc["configs"][name]["success_rate"] == pytest.approx(rate)
        assert {r["scenario"] for r in rows} == set(doc["run"]["scene_ids"])
        # The funnel in the summary is the episodes' own.
        f = doc["configs"][name]["funnel"]
        assert (f["scenes"], f["success"]) == (3, sum(bool(r["success"]) for r in rows))
        assert f["first_contact"] == sum(bool(r["contacts"]) for r in rows if not r.get("error"))
        assert f["reversed"] == sum(
            r["reversed_at"] not in (None, "") and r["reversed_at"] == r["reversed_at"]
            and (r["success"] or float(r["decided_at"]) >= float(r["reversed_at"])) for r in rows)
    # The impact at the first contact (m/s, rad): a column each, empty (None / NaN / "")
    # when the episode had no contact or the extension does not report it.
    for r in table:
        for k in ("impact_speed", "impact_angle"):
            assert k in r, k
            v = r[k]
            if v not in (None, "") and v == v:
                assert float(v) >= 0.0, (k, v)
        # Where the first touch landed on the target (body frame, m): within its footprint
        # (4.51 m × 1.61 m, c.g. 2.12 m behind the front), and only with a contact.
        x, y = r["impact_x"], r["impact_y"]
        if x not in (None, "") and x == x:
            assert int(r["contacts"]) >= 1
            assert -2.45 <= float(x) <= 2.17 and abs(float(y)) <= 0.86, (x, y)
        # The target's speed when it first came within ε_ψ of the reversed heading.
        v = r["reversed_speed"]
        if v not in (None, "") and v == v:
            assert float(v) >= 0.0 and float(r["reversed_at"]) > 0.0


TEXTBOOK = REPO / "data" / "textbook" / "scenarios.jsonl"


@pytest.fixture(scope="module")
def textbook_run(tmp_path_factory):
    """Six textbook PIT scenes (straight dry highway, no obstacles), simulated clock: the
    outcomes are the same on any machine."""
    tmp = tmp_path_factory.mktemp("textbook")
    proc = subprocess.run(picopit_cmd() + ["bench", "--scenarios", str(TEXTBOOK), "--models", str(MODELS),
                                           "--limit", "6", "--clock", "simulated", "--workers", "2",
                                           "--out", "run", "--no-progress"],
                          cwd=tmp, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return json.loads((tmp / "run" / "summary.json").read_text()), tmp / "run"


def test_the_upper_layer_pits_textbook_scenes_and_the_ablation_does_not(textbook_run):
    doc, _ = textbook_run
    successes = {name: c["successes"] for name, c in doc["configs"].items()}
    for name in ("4dof", "pinn", "picopinn"):
        assert successes[name] >= 4, successes
    assert successes["picopinn_no_upper"] <= 1, successes


def test_representative_cases_are_drawn_and_logged(textbook_run):
    """A success case is drawn whenever the PicoPINN saved a scene and a failure case whenever
    it lost one, each with its steps and summary in cases.mcap."""
    doc, run = textbook_run
    pico = doc["configs"]["picopinn"]
    present = {"success": pico["successes"] > 0, "failure": pico["successes"] < pico["episodes"]}
    assert any(present.values())
    for kind, there in present.items():
        assert (run / f"case_{kind}.png").exists() == there, kind
    reader = pytest.importorskip("mcap.reader")
    steps = {}
    with open(run / "cases.mcap", "rb") as fh:
        r = reader.make_reader(fh)
        topics = {c.topic for c in r.get_summary().channels.values()}
        for kind, there in present.items():
            assert (f"/{kind}/summary" in topics) == there, kind
            if there:
                msgs = [json.loads(m.data) for _, _, m in r.iter_messages(topics=[f"/{kind}/step"])]
                assert msgs and {"time", "target", "bullet", "command", "phase"} <= set(msgs[0])
                assert msgs[-1]["time"] > msgs[0]["time"]
                steps[kind] = len(msgs)
                # A log that Foxglove opens: the scene, transforms and poses with the Foxglove
                # SDK's schemas, every message valid against its schema (tests/foxglove_check.py).
                assert {f"/{kind}/{t}" for t in ("scene", "tf", "bullet/pose", "target/pose")} <= topics
    pytest.importorskip("google.protobuf")
    pytest.importorskip("jsonschema")
    from foxglove_check import check_recording

    rec = check_recording(run / "cases.mcap")
    for kind, n in steps.items():
        assert rec.counts[f"/{kind}/scene"] == n, kind


@pytest.mark.parametrize("args, needle", [
    (["--configs", "4dof,fivedof"], "--configs: unknown configuration 'fivedof'"),
    (["--configs", ""], "--configs: no configuration"),
    (["--configs", "pinn,pinn"], "--configs: a configuration is repeated"),
    (["--limit", "0"], "--limit = 0"),
    (["--uncertainty", '{"latency": 9}'], "uncertainty.latency"),
    (["--uncertainty", "[1]"], "--uncertainty"),
    (["--clock", "sundial"], "--clock"),
])
def test_bad_options_are_refused_with_a_message(tmp_path, monkeypatch, capsys, args, needle):
    from picopit.cli import main

    monkeypatch.chdir(tmp_path)
    rc = main(["bench", "--scenarios", str(SCENARIOS), "--models", str(MODELS), *args, "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert needle in err
    if "fivedof" in needle:
        assert "picopinn_no_upper" in err, "lists the known configurations"
    assert not (tmp_path / "runs").exists()


def test_the_default_scene_set_is_a_fixed_stratified_subset():
    from picopit.bench import SUBSET_SIZE, stratified_subset

    scenarios = picopit.load_scenarios(str(SCENARIOS))
    a = stratified_subset(scenarios)
    assert a == stratified_subset(scenarios), "deterministic"
    assert len(a) == SUBSET_SIZE == len(set(a))
    strata = {}
    for sc in scenarios:
        strata.setdefault((sc["category"], sc["adhesion"]), 0)
        strata[(sc["category"], sc["adhesion"])] += 1
    for key, count in strata.items():
        got = sum((scenarios[i]["category"], scenarios[i]["adhesion"]) == key for i in a)
        share = SUBSET_SIZE * count / len(scenarios)
        assert max(1, int(share)) <= got <= int(share) + 1, (key, got, share)
    assert len(stratified_subset(scenarios[:10], 128)) == 10


def test_the_contact_figure_bins_success_by_value_and_skips_missing_ones():
    from picopit.bench_figures import _binned_success

    rows = [{"v": 0.5, "success": True}, {"v": 1.5, "success": False}, {"v": 1.7, "success": True},
            {"v": None, "success": True}, {"v": float("nan"), "success": True}, {"v": 9.0, "success": True}]
    rate, n = _binned_success(rows, "v", (0.0, 1.0, 2.0, 3.0))
    # The episodes without the value, and the one beyond the last edge, count nowhere.
    assert n.tolist() == [1, 2, 0]
    assert rate[0] == 100.0 and rate[1] == 50.0 and np.isnan(rate[2])


def test_the_episode_binding_refuses_bad_input_and_records_on_request():
    line = SCENARIOS.read_text().splitlines()[0]
    with pytest.raises(picopit.EpisodeError, match="uncertainty.latency"):
        picopit.run_episode(line, '{"uncertainty": {"latency": "x"}}', 0, models_dir=str(MODELS))
    with pytest.raises(picopit.EpisodeError, match="known: 4dof"):
        picopit.run_episode(line, "fivedof", 0, models_dir=str(MODELS))
    with pytest.raises(picopit.ScenarioError, match="mu"):
        sc = json.loads(line)
        sc["mu"] = 9.0
        picopit.run_episode(json.dumps(sc), "4dof", 0, models_dir=str(MODELS))
    with pytest.raises(picopit.EpisodeError, match="nonexistent"):
        picopit.run_episode(line, "pinn", 0, models_dir="/nonexistent")
    sc = json.loads(line)
    sc["t_max"] = 1.0
    r = picopit.run_episode(json.dumps(sc), "4dof", 3, record=True, models_dir=str(MODELS))
    assert r["seed"] == 3 and r["decided_at"] is not None and r["decided_at"] <= 1.0 + 1e-9
    traj = r["trajectory"]
    assert traj.shape == (r["control_steps"], len(picopit.trajectory_columns()))
    t = traj[:, picopit.trajectory_columns().index("time")]
    assert np.all(np.diff(t) > 0) and t[-1] == pytest.approx(r["sim_time"])
    assert len(r["ctrl_times_ms"]) == r["ctrl_count"]
    assert picopit.episode_config("picopinn_no_upper")["controller"]["upper_layer"] is False


def test_ray_runs_the_same_episodes_as_local_processes():
    pytest.importorskip("ray")
    from picopit import bench

    # The simulated clock: with wall-clock time budgets a loaded machine changes outcomes.
    cfg = bench.BenchConfig(scenarios=SCENARIOS, models=MODELS, configs=("4dof",), limit=2, workers=2,
                            cases=False, figures=False, clock="simulated").validate()
    local = bench.run(cfg, progress=False)
    cfg.ray_address = "local"
    remote = bench.run(cfg, progress=False)
    key = lambda rows: [(r["config"], r["index"], r["success"], r["cause"], r["contacts"]) for r in rows]  # noqa: E731
    assert key(remote.rows) == key(local.rows)
    assert remote.summary["4dof"]["episodes"] == 2


def test_the_exact_mcnemar_test_and_the_paired_counts():
    from picopit.bench import mcnemar_exact_p, paired

    assert mcnemar_exact_p(0, 0) == 1.0 and mcnemar_exact_p(3, 3) == 1.0
    assert mcnemar_exact_p(0, 5) == pytest.approx(2 / 32)           # 2 · 0.5^5
    assert mcnemar_exact_p(1, 9) == pytest.approx(2 * 11 / 1024)     # 2 · (1 + 10) / 2^10
    assert mcnemar_exact_p(9, 1) == mcnemar_exact_p(1, 9)
    assert mcnemar_exact_p(100, 74) == pytest.approx(0.0577, abs=5e-4)  # full run, 4-DOF vs PINN
    rows = [{"config": c, "index": i, "success": s} for c, i, s in (
        ("x", 0, True), ("x", 1, True), ("x", 2, False), ("x", 3, True),
        ("y", 0, True), ("y", 1, False), ("y", 2, True), ("y", 4, True))]
    (p,) = paired(rows, ("x", "y")).values()
    # scene 3 only x ran, scene 4 only y: neither counts
    assert (p["scenes"], p["only_a"], p["only_b"], p["both"]) == (3, 1, 1, 1)
    assert p["mcnemar_p"] == 1.0


def test_success_by_target_speed_counts_bands_and_speeds_at_reversal():
    from picopit.bench_summary import by_speed, markdown

    meta = {0: {"target_speed": 8.0}, 1: {"target_speed": 12.0}, 2: {"target_speed": 14.9},
            3: {"target_speed": 15.0}, 4: {"target_speed": 22.0}, 5: {"target_speed": 25.0}}
    nan = float("nan")
    rows = [
        {"index": 0, "success": True, "reversed_at": 3.0, "reversed_speed": 1.0},
        {"index": 1, "success": False, "reversed_at": None, "reversed_speed": None},
        {"index": 2, "success": True, "reversed_at": 4.0, "reversed_speed": 3.0},
        {"index": 3, "success": False, "reversed_at": nan, "reversed_speed": nan},  # never reversed
        {"index": 4, "success": False, "reversed_at": 5.0, "reversed_speed": 12.0},
        {"index": 5, "success": False, "reversed_at": 5.5, "reversed_speed": 14.0},
    ]
    b = {x["band"]: x for x in by_speed(rows, meta)}
    assert [b[k]["episodes"] for k in ("< 10", "10–15", "15–20", "≥ 20")] == [1, 2, 1, 2]
    assert b["10–15"]["success_rate"] == pytest.approx(50.0) and b["10–15"]["reversed_rate"] == pytest.approx(50.0)
    assert b["10–15"]["reversed_speed_success_median"] == 3.0
    assert b["10–15"]["reversed_speed_lost_median"] is None
    assert b["15–20"]["reversed_rate"] == 0.0 and b["15–20"]["reversed_speed_lost_median"] is None
    # The fast targets: both turned round, both lost, at 12 and 14 m/s.
    assert b["≥ 20"]["success_rate"] == 0.0 and b["≥ 20"]["reversed_rate"] == 100.0
    assert b["≥ 20"]["reversed_speed_lost_median"] == pytest.approx(13.0)
    md = markdown({"x": {"by_speed": list(b.values())}})
    assert "| x | ≥ 20 | 2 | 0.0 | 100.0 | 13.0 | – |" in md


def test_success_by_driver_counts_contacts_reversals_and_what_the_reversed_kept():
    from picopit.bench_summary import by_driver, markdown

    meta = {0: {"driver": "brake"}, 1: {"driver": "brake"}, 2: {"driver": "brake"},
            3: {"driver": "lane_keep"}, 4: {"driver": None}}
    rows = [
        {"index": 0, "success": True, "contacts": 1, "reversed_at": 4.0},
        {"index": 1, "success": False, "contacts": 2, "reversed_at": 5.0},  # turned round, lost after
        {"index": 2, "success": False, "contacts": 0, "reversed_at": None},  # lost before contact
        {"index": 3, "success": False, "contacts": 1, "reversed_at": float("nan")},  # lost in the push
        {"index": 4, "success": True, "contacts": 1, "reversed_at": 3.0},  # no driver named: left out
    ]
    b = {x["driver"]: x for x in by_driver(rows, meta)}
    assert list(b) == ["none", "lane_keep", "brake", "counter_steer"]
    assert b["brake"]["episodes"] == 3
    assert b["brake"]["contact_rate"] == pytest.approx(200 / 3)
    assert b["brake"]["reversed_rate"] == pytest.approx(200 / 3)
    assert b["brake"]["success_rate"] == pytest.approx(100 / 3)
    assert b["brake"]["reversed_success_rate"] == pytest.approx(50.0)
    assert (b["lane_keep"]["contact_rate"], b["lane_keep"]["reversed_rate"]) == (100.0, 0.0)
    assert b["lane_keep"]["reversed_success_rate"] is None
    assert b["none"]["episodes"] == 0 and b["none"]["success_rate"] is None
    md = markdown({"x": {"by_driver": list(b.values())}})
    assert "| x | brake | 3 | 66.7 | 66.7 | 33.3 | 50.0 |" in md
    assert "| x | none | 0 | – | – | – | – |" in md


def test_curve_side_is_the_side_of_the_curve_the_first_contact_came_from():
    from picopit.bench import curve_direction
    from picopit.bench_summary import by_curve_side, curve_side, episode_table, markdown

    assert curve_direction({"road": {"radius": -95.0}}) == -1.0
    assert curve_direction({"road": {"radius": 250.0}}) == 1.0
    assert curve_direction({"road": {"lanes": 2}}) is None
    left, right, straight = {"curve": 1.0}, {"curve": -1.0}, {"curve": None}
    # impact_y > 0: the bullet touched the target's left side.
    assert curve_side({"contacts": 1, "impact_y": 0.9}, left) == "inside"
    assert curve_side({"contacts": 1, "impact_y": -0.9}, left) == "outside"
    assert curve_side({"contacts": 1, "impact_y": 0.9}, right) == "outside"
    assert curve_side({"contacts": 2, "impact_y": -0.9}, right) == "inside"
    assert curve_side({"contacts": 1, "impact_y": 0.9}, straight) is None
    assert curve_side({"contacts": 0, "impact_y": None}, left) is None
    assert curve_side({"contacts": 1, "impact_y": float("nan")}, left) is None

    meta = {0: left, 1: right, 2: right, 3: left, 4: straight, 5: left}
    rows = [
        {"index": 0, "success": True, "contacts": 1, "impact_y": 0.8, "reversed_at": 4.0},  # inside, saved
        {"index": 1, "success": False, "contacts": 1, "impact_y": 0.8, "reversed_at": 5.0},  # outside, lost after
        {"index": 2, "success": False, "contacts": 1, "impact_y": 0.7, "reversed_at": None},  # outside, in the push
        {"index": 3, "success": True, "contacts": 1, "impact_y": -0.8, "reversed_at": 4.5},  # outside, saved
        {"index": 4, "success": True, "contacts": 1, "impact_y": 0.8, "reversed_at": 4.0},  # straight: left out
        {"index": 5, "success": False, "contacts": 0, "impact_y": None, "reversed_at": None},  # untouched: left out
    ]
    b = {x["curve_side"]: x for x in by_curve_side(rows, meta)}
    assert list(b) == ["inside", "outside"]
    assert (b["inside"]["episodes"], b["inside"]["success_rate"], b["inside"]["reversed_success_rate"]) == (1, 100.0, 100.0)
    assert b["outside"]["episodes"] == 3
    assert b["outside"]["reversed_rate"] == pytest.approx(200 / 3)
    assert b["outside"]["success_rate"] == pytest.approx(100 / 3)
    assert b["outside"]["reversed_success_rate"] == pytest.approx(50.0)
    md = markdown({"x": {"by_curve_side": list(b.values())}})
    assert "| x | outside | 3 | 66.7 | 33.3 | 50.0 |" in md
    meta_full = {i: {**m, "id": f"sc-{i}", "category": "curved", "road": "curved", "adhesion": "high",
                     "params": "full_size", "mu": 0.9} for i, m in meta.items()}
    assert [e["curve_side"] for e in episode_table(rows, meta_full)] == [
        "inside", "outside", "outside", "outside", None, None]


def test_controller_settings_files_override_the_presets_and_bad_ones_are_named(tmp_path, monkeypatch, capsys):
    from picopit.cli import main

    monkeypatch.chdir(tmp_path)
    base = ["bench", "--scenarios", str(SCENARIOS), "--models", str(MODELS), "--no-progress", "--limit", "1",
            "--configs", "picopinn", "--clock", "simulated", "--no-figures"]
    (tmp_path / "bad.toml").write_text("[planner]\nwindow = -1.0\n")
    (tmp_path / "broken.toml").write_text("[planner\n")
    (tmp_path / "off.toml").write_text("upper_layer = false\n")
    (tmp_path / "nan.toml").write_text("[planner]\napproach_accel_min = nan\n")
    for args, needle in ((["--controller-config", "bad.toml"], "--controller-config: "),
                         (["--controller-config-half-scale", "bad.toml"], "--controller-config-half-scale: "),
                         (["--controller-config", "broken.toml"], "--controller-config broken.toml: "),
                         (["--controller-config", "missing.toml"], "missing.toml: No such file"),
                         (["--controller-config", "nan.toml"], "`planner.approach_accel_min` must be a finite number"),
                         # Each override is checked alone: the bad one is named, not the first given.
                         (["--uncertainty", '{"latency": 0.02}', "--controller-config", "bad.toml"],
                          "--controller-config: ")):
        assert main(base + args) == 2
        err = capsys.readouterr().err
        assert needle in err, err
        if "bad.toml" in args:
            assert "window" in err, "names the field"
    # The settings reach the controller: with the upper layer switched off nothing plans.
    assert main(base + ["--controller-config", "off.toml", "--out", "off"]) == 0
    doc = json.loads((tmp_path / "off" / "summary.json").read_text())
    assert doc["configs"]["picopinn"]["plan_ms_median"] is None
    assert doc["run"]["controller"] == {"upper_layer": False} and doc["run"]["controller_half_scale"] is None
    assert main(base + ["--out", "on"]) == 0
    assert json.loads((tmp_path / "on" / "summary.json").read_text())["configs"]["picopinn"]["plan_ms_median"] > 0
