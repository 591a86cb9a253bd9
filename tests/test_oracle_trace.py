"""``picopit oracle`` (the ideal-PIT bound, its tiers) and ``picopit trace`` (one episode step
by step): they report what the core computes, and bad input is one line with exit status 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from picopit import _core, bench, cli, oracle, trace

ROOT = Path(__file__).resolve().parents[1]
TEXTBOOK = ROOT / "data" / "textbook" / "scenarios.jsonl"
TRIALS = ROOT / "data" / "trials" / "half_scale.jsonl"
DATASET = ROOT / "data" / "scenarios.jsonl"


def test_oracle_finds_a_feasible_push_on_two_textbook_scenes(tmp_path, capsys):
    """Textbook PIT scenes (dry straight highway, lane-keeping target): a rear-quarter shove
    saves each, after the bullet can be there; the summary counts them."""
    out = tmp_path / "oracle.json"
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--n", "2", "--scene-lines", "--no-progress",
                   "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    doc = json.loads(out.read_text())
    assert len(doc["scenes"]) == 2
    for s in doc["scenes"]:
        r = s["result"]
        assert r["feasible"] and r["shove"]["time"] >= r["t_reach"] - 1e-9, s
        assert r["shove"]["decided_at"] > r["shove"]["time"] + 1.0, "a spin takes time"
        assert r["shove"]["dv"] in doc["settings"]["shoves"]
        assert f"{s['id']} feasible: shove at" in text
    assert doc["summary"]["all"] == {"n": 2, "share": {"feasible": 100.0}}
    assert "| all | 2 | 100.0 % |" in text
    assert "| category straight_highway | 2 |" in text and "| driver lane_keep | 2 |" in text


def test_a_shove_of_nothing_saves_no_scene():
    """The bound comes from the push: with only zero-size shoves no scene is feasible."""
    scenes = oracle.select(_core.load_scenarios(str(TEXTBOOK)), 0, 2)
    res = oracle.run(scenes, oracle.resolve_settings('{"shoves": [0.0]}', tiers=False), progress=False)
    assert [s["result"]["feasible"] for s in res.scenes] == [False, False]
    assert all(s["result"]["tried"] > 5 for s in res.scenes)
    assert res.summary()["all"]["share"] == {"feasible": 0.0}


def test_oracle_tiers_judge_choices_in_the_truth():
    """On a coarse grid: the tiers are shares in [0, 1]; what is robust is also feasible, and
    the expected success of the best box is no more than the bound."""
    scenes = oracle.select(_core.load_scenarios(str(TEXTBOOK)), ids=["sc-00000"])
    settings = oracle.resolve_settings('{"shoves": [1.0, 1.5, 2.0, 2.5], "time_step": 0.25}', tiers=True)
    res = oracle.run(scenes, settings, tiers=True, progress=False)
    r = res.scenes[0]["result"]
    t = r["tiers"]
    assert list(t) == list(_core.oracle_tier_names()) == res.names
    assert all(0.0 <= v <= 1.0 for v in t.values())
    assert t["ideal"] == 1.0 and 0 < r["true_share"] <= 1
    assert t["robust-tv"] <= min(t["robust-t"], t["robust-v"]) <= t["ideal"]
    assert t["ideal-exp"] <= t["ideal"] and t["held-exp"] <= t["ideal-exp"] + 1e-12
    assert r["shoves"] > 0 and r["shoves"] % 8 == 0  # 4 sizes x 2 sides x the times


def test_oracle_subset_is_the_benchmarks_stratified_subset():
    """--subset N picks the scenes picopit bench would run for N: the same ids, in file order."""
    scenarios = [json.loads(line) for line in open(DATASET)]
    chosen = oracle.select(scenarios, subset=16)
    assert [s["id"] for s in chosen] == [scenarios[i]["id"] for i in bench.stratified_subset(scenarios, 16)]
    assert len({(s["category"], s["adhesion"]) for s in chosen}) >= 6, "every stratum is drawn"


def _episodes(tmp_path: Path, rows: str) -> Path:
    path = tmp_path / "episodes.csv"
    path.write_text("config,scenario,success,impact_y\n" + rows)
    return path


def test_oracle_keeps_the_side_a_run_pushed_from(tmp_path, capsys):
    """--sides-of RUN: a scene the run's controller pushed is shoved only on the side of its
    first contact (impact_y > 0: the target's left), whichever side the free search would
    find first; a scene without a contact, or pushed only by another configuration, keeps
    both sides."""
    run = _episodes(tmp_path, "picopinn,sc-00000,False,-0.8\npicopinn,sc-00002,True,0.7\n"
                              "4dof,sc-00004,False,-0.9\npicopinn,sc-00004,False,\n")
    out = tmp_path / "oracle.json"
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00000,sc-00002,sc-00004",
                   "--settings", '{"shoves": [0.5, 1.0, 1.5, 2.0], "time_step": 0.25}', "--sides-of", str(run),
                   "--no-progress", "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "2 of them tried only on the side picopinn pushed from" in text
    scenes = {s["id"]: s for s in json.loads(out.read_text())["scenes"]}
    assert scenes["sc-00000"]["sides"] == [-1.0] and scenes["sc-00002"]["sides"] == [1.0]
    assert "sides" not in scenes["sc-00004"]
    # Unrestricted, the search tries the left first and saves sc-00000 from there.
    free = oracle.run(oracle.select(_core.load_scenarios(str(TEXTBOOK)), ids=["sc-00000"]),
                      oracle.resolve_settings('{"shoves": [0.5, 1.0, 1.5, 2.0], "time_step": 0.25}', False),
                      progress=False)
    assert free.scenes[0]["result"]["shove"]["side"] == 1.0
    for sid, side in (("sc-00000", -1.0), ("sc-00002", 1.0)):
        r = scenes[sid]["result"]
        assert r["feasible"] and r["shove"]["side"] == side, (sid, r)
    # The other configuration's side is not taken: sc-00004 tried both sides at its first size.
    assert scenes["sc-00004"]["result"]["tried"] > scenes["sc-00002"]["result"]["tried"]


@pytest.mark.parametrize("rows, argv, words", [
    ("picopinn,sc-00000,False,left\n", [], "row 1: impact_y 'left'"),
    ("4dof,sc-00000,False,0.5\n", [], "--config picopinn: not in"),
    ("picopinn,sc-00000,False,0.5\n", ["--config", "pinn"], "it has picopinn"),
])
def test_oracle_refuses_a_bad_sides_of_run_naming_it(tmp_path, capsys, rows, argv, words):
    run = _episodes(tmp_path, rows)
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00000", "--no-progress",
                   "--sides-of", str(run), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err


def test_oracle_refuses_a_run_without_the_impact_column(tmp_path, capsys):
    run = tmp_path / "episodes.csv"
    run.write_text("config,scenario,success\npicopinn,sc-00000,False\n")
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00000", "--no-progress",
                   "--sides-of", str(run)])
    err = capsys.readouterr().err
    assert rc == 2 and "impact_y" in err and "Traceback" not in err, err
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00000", "--no-progress",
                   "--sides-of", str(tmp_path / "missing")])
    err = capsys.readouterr().err
    assert rc == 2 and "no such run" in err, err


@pytest.mark.parametrize("argv, words", [
    (["--settings", '{"shoves": []}'], "shoves"),
    (["--settings", '{"time_step": 0}'], "time_step"),
    (["--settings", '{"shove": [1]}'], "shove"),
    (["--settings", "[1"], "not JSON"),
    (["--ids", "sc-99999"], "sc-99999"),
    (["--first", "100000"], "--first"),
    (["--workers", "0"], "--workers"),
    (["--subset", "0"], "--subset"),
    (["--subset", "8", "--n", "4"], "--subset"),
    (["--config", "pinn"], "--sides-of"),
])
def test_oracle_refuses_bad_input_naming_it(capsys, argv, words):
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err


def test_trace_shows_the_contact_and_the_outcome(tmp_path, capsys):
    """A textbook scene traced: the table has the steps in contact (every one, whatever
    --every), the PIT phase, and the metrics the episode result holds; the CSV has every step
    with the road frame, and the bullet starts behind the target in its lane beside it."""
    csv = tmp_path / "trace.csv"
    png = tmp_path / "trace.png"
    rc = cli.main(["trace", "sc-00000", "--scenarios", str(TEXTBOOK), "--every", "50", "--csv", str(csv),
                   "--plot", str(png), "--plans"])
    out = capsys.readouterr().out
    assert rc == 0, out
    lines = out.splitlines()
    assert lines[0].startswith("scene sc-00000: straight_highway")
    head = lines[1].split()
    rows = [dict(zip(head, l.split())) for l in lines[2:] if l[:6].strip().replace(".", "").isdigit()]
    contact = [r for r in rows if "yes" in r.values()]
    assert contact, out
    assert any(" pit " in f" {' '.join(r.values())} " for r in rows)
    plans = [l for l in lines if l.startswith("plan at")]
    assert any(": pit, " in l and " side, push " in l and "peak" in l and " kN s" in l for l in plans), \
        "the PIT plan, its side and its push"
    metrics = [l for l in lines if l.startswith("metrics:")][0]
    assert "contacts " in metrics and "success " in metrics
    data = np.genfromtxt(csv, delimiter=",", names=True)
    n_contact = int((data["contact_fn"] > 0).sum())
    assert n_contact == len(contact) > 0, "every step in contact is shown"
    assert len(data) > len(rows), "--every thins the rest"
    first = data[0]
    assert first["bullet_s"] < first["target_s"] and abs(first["bullet_d"] - first["target_d"]) > 2.0
    assert np.all(np.abs(data["target_dpsi"]) <= np.pi + 1e-9)
    assert png.stat().st_size > 10_000


def test_trace_names_why_a_plan_aborts(capsys):
    """Dataset scene sc-01093 (a curve) ends "decision infeasible": its plans say why they
    abort (the infeasibility the upper layer found) and every plan names its side."""
    rc = cli.main(["trace", "sc-01093", "--scenarios", str(DATASET), "--every", "100", "--plans"])
    out = capsys.readouterr().out
    assert rc == 0, out
    plans = [l for l in out.splitlines() if l.startswith("plan at")]
    aborts = [l for l in plans if ": abort" in l]
    assert aborts, out
    assert all(": abort (" in l and ")," in l for l in aborts), aborts
    assert all(" left side, " in l or " right side, " in l for l in plans), plans
    assert not any(": chase (" in l or ": pit (" in l for l in plans), "no reason without an abort"


def test_trace_matches_the_episode_the_benchmark_runs():
    """The trace is the benchmark's episode: the same metrics as _core.run_episode on the same
    configuration, and the road frame agrees with road_poses."""
    scene = trace.find_scene(TEXTBOOK, "sc-00002")
    t = trace.trace(scene, "4dof")
    r = _core.run_episode(json.dumps(scene), trace.config_text("4dof"), 0)
    for k in ("success", "contacts", "contact_at", "decided_at", "terminal_heading_error"):
        assert t.result[k] == r[k], k
    c = t.columns
    back = np.asarray(_core.road_poses(json.dumps(scene["road"]), c["target_s"], c["target_d"]))
    assert np.allclose(back[:, 0], c["target_x"], atol=1e-6) and np.allclose(back[:, 1], c["target_y"], atol=1e-6)


def test_trace_sets_each_plan_against_what_the_target_then_did():
    """Every plan's prediction starts from the target state the controller measured when it
    planned (the recorded sample at the plan's time), and its line says how far the target
    was from the prediction at the prediction's last recorded step."""
    t = trace.trace(trace.find_scene(TEXTBOOK, "sc-00002"), "4dof")
    c = t.columns
    plans = t.result["plans"]
    assert len(plans) >= 3
    checked = 0
    for p in plans:
        times, states = np.asarray(p["predicted_time"]), np.asarray(p["predicted_target"])
        assert states.shape == (times.size, 8) and times[0] == pytest.approx(p["time"])
        i = int(np.argmin(np.abs(c["time"] - p["time"])))
        if abs(c["time"][i] - p["time"]) < 1e-9:
            measured = [c[k][i] for k in ("target_vx", "target_vy", "target_psi", "target_r",
                                          "target_p", "target_phi", "target_x", "target_y")]
            assert np.allclose(states[0], measured, atol=1e-9), p["time"]
            checked += 1
        err = t.prediction_error(p)
        assert err is not None and err["distance"] >= 0.0 and abs(err["heading"]) <= np.pi
        assert times[0] < err["time"] <= c["time"][-1] + 1e-9
    assert checked >= len(plans) - 1, "only the plan before the first sample is unrecorded"
    lines = t.plan_lines()
    assert len(lines) == len(plans) and all(" off the prediction" in l for l in lines), lines


def test_a_bullet_held_back_for_traffic_stays_behind_the_target_and_the_trace_says_so():
    """`sc-00285`: cars stopped in the lanes ahead on a right-hand curve. The bullet, behind
    the target in its lane, is held back there (its stand-off pose beside the target would
    run into them) until the target has passed them; the plans record it, the plan lines
    say it, and while held back the bullet stays behind the target's rear bumper."""
    t = trace.trace(trace.find_scene(DATASET, "sc-00285"), "picopinn")
    plans = t.result["plans"]
    held = [p["hold_back"] for p in plans]
    assert held[0] and not all(held), held
    for p, line in zip(plans, t.plan_lines()):
        assert ("held back behind the target" in line) == p["hold_back"], line
    # The episode's summary (a column of the benchmark's episodes table) has the last one.
    assert t.result["held_back_until"] == max(p["time"] for p in plans if p["hold_back"])
    c = t.columns
    release = next(p["time"] for p in plans if not p["hold_back"])
    # In the target's frame: the bullet's c.g. ahead (+) or behind (-) the target's.
    dx, dy = c["bullet_x"] - c["target_x"], c["bullet_y"] - c["target_y"]
    ahead = np.cos(c["target_psi"]) * dx + np.sin(c["target_psi"]) * dy
    during = (c["time"] >= 1.5) & (c["time"] < release)
    assert during.sum() > 20
    # 4.5 m: a car length, so the two do not overlap along the road.
    assert ahead[during].max() < -4.5, ahead[during].max()


def test_trace_runs_a_half_scale_trial_case_with_its_controller_settings(capsys):
    """The half-scale trials in process: the trial file, its controller settings TOML."""
    rc = cli.main(["trace", "R1", "--scenarios", str(TRIALS), "--every", "100",
                   "--controller-config", str(ROOT / "configs" / "controller_half_scale.toml")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert out.startswith("scene R1:") and "half_scale" in out.splitlines()[0]


@pytest.mark.parametrize("argv, words", [
    (["sc-99999"], "sc-99999: no such scene"),
    (["sc-00000", "--config", "nope"], "nope"),
    (["sc-00000", "--config", '{"preset": "picopinn", "uncertainty": {"latency": -1}}'], "latency"),
    (["sc-00000", "--controller-config", "/nonexistent.toml"], "/nonexistent.toml"),
    (["sc-00000", "--every", "0"], "--every"),
])
def test_trace_refuses_bad_input_naming_it(capsys, argv, words):
    rc = cli.main(["trace", "--scenarios", str(TEXTBOOK), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err


def test_trace_names_a_non_finite_controller_setting(tmp_path, capsys):
    bad = tmp_path / "nan.toml"
    bad.write_text("[planner]\napproach_accel_min = nan\n")
    rc = cli.main(["trace", "--scenarios", str(TEXTBOOK), "sc-00000", "--controller-config", str(bad)])
    err = capsys.readouterr().err
    assert rc == 2 and "`planner.approach_accel_min` must be a finite number" in err, err


def test_trace_steps_the_models_through_the_push_that_was_delivered(capsys):
    """Textbook `sc-00002` (PicoPINN): the recorded contact of every step is the input a
    target model takes (its point on the target's side, its normal the side's, pointing into
    the target; zeros apart), and the learned models stepped through the recorded push from
    the state before it follow the truth's turn, which the contact carries: without it the
    same model misses by far."""
    t = trace.trace(trace.find_scene(TEXTBOOK, "sc-00002"), "picopinn")
    c = t.columns
    push = t.first_push()
    assert push is not None and len(push) >= 5
    touch = c["contact_fn"] > 0
    apart = ~touch
    assert np.all(c["contact_gamma"][apart] == 0.0) and np.all(c["contact_px"][apart] == 0.0)
    length, width = 4.508, 1.61
    px, py = c["contact_px"][touch], c["contact_py"][touch]
    assert np.all(np.abs(px) <= length) and np.allclose(np.abs(py), width / 2, atol=0.15)
    # Normal from the bullet into the target: on the target's left side it points to its right.
    side_normal = c["target_psi"][touch] - np.sign(py) * np.pi / 2
    off = np.array([_core.wrap_angle(a) for a in c["contact_gamma"][touch] - side_normal])
    assert np.all(np.abs(off) < 0.4), off
    pm = t.push_models()
    dt = c["time"][1] - c["time"][0]
    assert pm["impulse"] == pytest.approx(c["contact_fn"][push.start:push.stop].sum() * dt)
    assert pm["start"] == pytest.approx(c["time"][push.start - 1]) and pm["end"] == pytest.approx(c["time"][push.stop - 1])
    end = pm["rows"][0]
    assert end["time"] == pytest.approx(pm["end"]) and len(pm["rows"]) == 2
    truth = end["truth"][0]
    assert abs(truth) > np.radians(20), "the push turned the target"
    for name in ("pinn", "picopinn"):
        assert abs(end[name][0] - truth) < np.radians(15), (name, end[name], truth)
    assert abs(end["free"][0] - truth) > np.radians(40), "without the contact the model misses the turn"
    assert end["plan"] is not None, "the plan before the contact predicts the push's end"
    rc = cli.main(["trace", "sc-00002", "--scenarios", str(TEXTBOOK), "--every", "400", "--push-models"])
    lines = capsys.readouterr().out.splitlines()
    assert rc == 0
    i = next(i for i, l in enumerate(lines) if l.startswith("push "))
    assert " kN s, contact point " in lines[i] and "truth" in lines[i + 1] and "picopinn" in lines[i + 1]
    assert len(lines[i + 2].split()) == 1 + 6 * 3 and lines[i + 4].startswith("metrics:")


def test_trace_says_when_there_was_no_push_to_step_the_models_through():
    """`sc-01093` ends "decision infeasible" before any contact: no push to check."""
    t = trace.trace(trace.find_scene(DATASET, "sc-01093"), "picopinn")
    assert t.first_push() is None and t.push_models() is None
    assert t.push_model_lines() == ["push models: no contact recorded (after the first step)"]


def _episodes_csv(path: Path, ids, contact="2.5", config="picopinn") -> Path:
    lines = ["config,scenario,params,contact_at,success"]
    lines += [f"{config},{i},full_size,{contact},true" for i in ids]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_push_models_sets_the_models_and_the_plans_against_the_delivered_pushes(tmp_path, capsys):
    """Three textbook episodes a run touched: each first push traced again; the learned
    models, given the delivered push, predict its turn within a quarter of the truth's."""
    run = _episodes_csv(tmp_path / "episodes.csv", ["sc-00000", "sc-00002", "sc-00004"])
    out = tmp_path / "pm.json"
    rc = cli.main(["push-models", str(run), "--scenarios", str(TEXTBOOK), "--n", "3", "--no-progress",
                   "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    doc = json.loads(out.read_text())
    assert doc["scenes"] == 3 and len(doc["pushes"]) == 3 and doc["turned"] >= 2
    for k in ("pinn", "picopinn"):
        s = doc["sources"][k]
        assert s["n"] == doc["turned"] and 0.75 < s["median"] < 1.25, (k, s)
    assert {p["scene"] for p in doc["pushes"]} == {"sc-00000", "sc-00002", "sc-00004"}
    assert all(p["impulse"] > 0 and -4.5 < p["point_x"] < 0 for p in doc["pushes"]), "rear-quarter pushes"
    assert all(0 < p["impact"] <= p["impulse"] and p["peak"] * 0.05 >= p["impact"] / 3 for p in doc["pushes"])
    d = doc["delivered"]
    assert d["impact"]["p10"] <= d["impact"]["median"] <= d["impact"]["p90"]
    assert "picopinn" in text and "off by more than half" in text


def test_push_models_draws_the_same_scenes_for_the_same_seed(tmp_path):
    from picopit import push_models

    run = _episodes_csv(tmp_path / "e.csv", [f"sc-{i:05d}" for i in range(0, 40, 2)])
    a = push_models.sample_scenes(run, "picopinn", "full_size", 5, 3)
    assert a == push_models.sample_scenes(run, "picopinn", "full_size", 5, 3) and len(a) == 5
    assert a != push_models.sample_scenes(run, "picopinn", "full_size", 5, 4)
    assert len(push_models.sample_scenes(run, "picopinn", "full_size", 500, 3)) == 20


@pytest.mark.parametrize("make, argv, words", [
    (lambda p: p.write_text("config,scenario,params,success\npicopinn,sc-00000,full_size,true\n"), [],
     "`contact_at`"),
    (lambda p: _episodes_csv(p, ["sc-99999"]), [], "sc-99999"),
    (lambda p: _episodes_csv(p, ["sc-00000"], contact=""), [], "touched the target"),
    (lambda p: _episodes_csv(p, ["sc-00000"]), ["--n", "0"], "--n 0"),
    (lambda p: _episodes_csv(p, ["sc-00000"]), ["--workers", "0"], "--workers 0"),
])
def test_push_models_refuses_bad_input_naming_it(tmp_path, capsys, make, argv, words):
    run = tmp_path / "episodes.csv"
    make(run)
    rc = cli.main(["push-models", str(run), "--scenarios", str(TEXTBOOK), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err


def test_push_models_refuses_a_road_the_learned_models_were_not_trained_on():
    """A scene at mu 1.1 (above the surrogates' training range) traced with the 4-DOF model:
    stepping the PINN through its push is refused naming mu, not run at another mu."""
    scene = trace.find_scene(TEXTBOOK, "sc-00002")
    scene.update(mu=1.1, adhesion="high")
    t = trace.trace(scene, "4dof")
    assert t.first_push() is not None
    with pytest.raises(trace.TraceError, match="mu"):
        t.push_models()
