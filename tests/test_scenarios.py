"""The PIT Scenario Dataset: the shipped file, the loader's errors, generation, KL."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import picopit
from picopit import _core
from picopit import scenarios as S

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data"


def first_line() -> dict:
    with open(DATA / "scenarios.jsonl") as fh:
        return json.loads(fh.readline())


def test_shipped_file_loads_and_matches_the_manifest():
    manifest = json.loads((DATA / "scenarios.manifest.json").read_text())
    assert S.sha256_file(DATA / "scenarios.jsonl") == manifest["sha256"]
    scenarios = picopit.load_scenarios(str(DATA / "scenarios.jsonl"))
    assert len(scenarios) == manifest["counts"]["retained"] == 2048
    assert manifest["counts"]["generated"] == 4500 and manifest["counts"]["priors"] == 117
    assert manifest["priors_sha256"] == S.sha256_file(DATA / "priors.csv")
    # The file is in the core's canonical form: loading and re-serialising changes nothing.
    assert S.jsonl_text(scenarios) == (DATA / "scenarios.jsonl").read_text()


def test_composition_is_near_the_target_shares():
    scenarios = picopit.load_scenarios(str(DATA / "scenarios.jsonl"))
    n = len(scenarios)
    for cat, share in S.TARGET_SHARES.items():
        got = sum(s["category"] == cat for s in scenarios) / n
        assert abs(got - share) < 0.03, (cat, got)
    bands = {b: sum(s["adhesion"] == b for s in scenarios) / n for b in S.ADHESION}
    # Every band well represented (the screen drops more low-μ races: 9.9 % are low).
    assert all(v > 0.05 for v in bands.values()), bands
    counts = [len(s["obstacles"]) for s in scenarios]
    assert min(counts) == 0 and max(counts) >= 5
    roles = {o["role"] for s in scenarios for o in s["obstacles"]}
    assert roles == {"forward_traffic", "roadside"}
    assert any(o["body"]["vx"] != 0 for s in scenarios for o in s["obstacles"])
    assert {s["params"] for s in scenarios} == {"full_size", "half_scale"}


def test_priors_table_is_valid():
    priors = S.load_priors(DATA / "priors.csv")
    assert len(priors) == 117
    assert all(p.source for p in priors)
    # The shipped table is the documented design.
    rows = S.design_priors()
    assert [r["prior_id"] for r in rows] == [p.prior_id for p in priors]


def _write(tmp_path: Path, lines) -> str:
    path = tmp_path / "bad.jsonl"
    path.write_text("".join(l + "\n" for l in lines))
    return str(path)


@pytest.mark.parametrize(
    "edit, field",
    [
        (lambda d: json.dumps(d)[:-5], "column"),          # bad JSON
        (lambda d: json.dumps({k: v for k, v in d.items() if k != "mu"}), "mu"),  # missing field
        (lambda d: json.dumps({**d, "t_max": "long"}), "t_max"),               # wrong type
        (lambda d: json.dumps({**d, "mu": 2.5}), "mu"),                        # out of range
        (lambda d: json.dumps({**d, "road": {**d["road"], "lanes": 0}}), "road.lanes"),
    ],
)
def test_a_malformed_line_names_line_and_field(tmp_path, edit, field):
    good = first_line()
    path = _write(tmp_path, [json.dumps(good), json.dumps({**good, "id": "other"}), edit(good)])
    with pytest.raises(picopit.ScenarioError) as e:
        picopit.load_scenarios(path)
    msg = str(e.value)
    assert msg.startswith("line 3:"), msg
    assert field in msg, msg
    assert isinstance(e.value, ValueError)


def test_validate_and_screen_one_line():
    good = first_line()
    d = picopit.validate_scenario_line(json.dumps(good), 4)
    assert d == good
    with pytest.raises(picopit.ScenarioError, match=r"^line 4: adhesion:"):
        picopit.validate_scenario_line(json.dumps({**good, "adhesion": "low" if good["adhesion"] != "low" else "high"}), 4)
    rep = picopit.screen_scenario(json.dumps(good))
    assert rep["verdict"] == "keep" and rep["t_reach"] > 0
    st = picopit.scenario_initial_states(json.dumps(good))
    assert st["bullet"].shape == (6,) and st["target"].shape == (8,)
    assert st["target"][0] == good["target"]["vx"]


def test_generation_is_deterministic_for_a_seed():
    priors = S.load_priors(DATA / "priors.csv")
    cfg = S.GenerateConfig(n=40, keep=24, seed=11, workers=2)
    a = S.generate(priors, cfg, progress=False)
    b = S.generate(priors, cfg, progress=False)
    assert S.jsonl_text(a.retained) == S.jsonl_text(b.retained)
    assert a.counts == b.counts and a.kl == b.kl
    c = S.generate(priors, S.GenerateConfig(n=40, keep=24, seed=12), progress=False)
    assert S.jsonl_text(c.retained) != S.jsonl_text(a.retained)
    assert len(a.retained) <= 24
    assert a.counts["generated"] == 40
    stages = sum(a.counts[k] for k in ("rule_rejected", "trivial", "impossible", "screened_keep"))
    assert stages == 40


def test_a_sample_the_format_refuses_is_rejected_not_fatal(monkeypatch):
    """An obstacle sampled on top of the target at t = 0 is refused by the scenario format;
    generation counts it as rejected and goes on."""
    priors = S.load_priors(DATA / "priors.csv")
    real = S.sample_scenario

    def sample(prior, index, seed_seq):
        s = real(prior, index, seed_seq)
        if index == 2:
            t = s["target"]
            s["obstacles"] = [{"role": "roadside", "body": {"x": t["s"], "y": t["d"], "heading": 0.0, "vx": 0.0,
                                                            "vy": 0.0, "length": 4.0, "width": 1.8}}]
        return s

    monkeypatch.setattr(S, "sample_scenario", sample)
    res = S.generate(priors, S.GenerateConfig(n=6, keep=6, seed=3), progress=False)
    assert res.counts["reasons"].get("rejected:invalid") == 1
    assert res.screens[2]["verdict"] == "rejected" and "overlaps" in res.screens[2]["reason"]
    assert all(s["id"] != res.generated[2]["id"] for s in res.retained)


def test_a_bullet_about_to_hit_an_obstacle_is_rejected():
    """Holding its lane and speed, a bullet 2 m behind a car parked in its lane hits it in
    about 0.1 s: no controller could have saved the scene, and the screen says so."""
    scenes = [json.loads(line) for line in (DATA / "scenarios.jsonl").read_text().splitlines()]
    good = next(s for s in scenes if "radius" not in s["road"] and abs(s["target"]["d"] - s["bullet"]["d"]) > 2.5)
    b = good["bullet"]
    good["obstacles"] = [{"role": "roadside", "body": {"x": b["s"] + 6.5, "y": b["d"], "heading": 0.0,
                                                       "vx": 0.0, "vy": 0.0, "length": 4.0, "width": 1.8}}]
    rep = picopit.screen_scenario(json.dumps(good))
    assert rep["verdict"] == "rejected" and rep["reason"].startswith("bullet_blocked"), rep
    # Parked 40 m ahead it is 2 s away: the bullet can steer round it, so this rule keeps it.
    good["obstacles"][0]["body"]["x"] = b["s"] + 40.0
    rep = picopit.screen_scenario(json.dumps(good))
    assert not rep["reason"].startswith("bullet_blocked"), rep


def test_the_shipped_dataset_regenerates_from_its_seed_in_part():
    """The first scenarios of a regeneration are the shipped ones (same priors, seed 0)."""
    priors = S.load_priors(DATA / "priors.csv")
    res = S.generate(priors, S.GenerateConfig(n=60, keep=10_000, seed=0), progress=False)
    shipped = {s["id"]: s for s in picopit.load_scenarios(str(DATA / "scenarios.jsonl"))}
    # Scenarios are sampled independently per index, so a shorter run reproduces a prefix.
    common = [s for s in res.retained if s["id"] in shipped]
    assert len(common) >= 20
    for s in common:
        assert s == shipped[s["id"]]


def test_kl_on_a_toy_case():
    p = np.array([0.5, 0.5, 0.0])
    q = np.array([0.25, 0.25, 0.5])
    assert S.kl_divergence(p, q) == pytest.approx(math.log(2.0))
    assert S.kl_divergence(q, q) == pytest.approx(0.0)
    # Unnormalised counts are normalised first.
    assert S.kl_divergence(np.array([2.0, 2.0, 0.0]), np.array([1.0, 1.0, 2.0])) == pytest.approx(math.log(2.0))
    with pytest.raises(ValueError):
        S.kl_divergence(np.array([1.0, 0.0]), np.array([1.0, 0.0, 0.0]))


def test_prior_mixture_of_uniform_ranges():
    edges = np.array([0.0, 1.0, 2.0, 4.0])
    assert np.allclose(S._uniform_mass(0.5, 2.5, edges), [0.25, 0.5, 0.25])
    assert np.allclose(S._uniform_mass(3.0, 3.0, edges), [0.0, 0.0, 1.0])


def test_bad_priors_name_line_and_column(tmp_path):
    text = (DATA / "priors.csv").read_text().splitlines()
    header = text[0].split(",")
    row = text[1].split(",")
    row[header.index("mu_lo")] = "abc"
    bad = tmp_path / "priors.csv"
    bad.write_text("\n".join([text[0], text[2], ",".join(row)]) + "\n")
    with pytest.raises(S.ScenarioGenError, match=r"line 3: mu_lo"):
        S.load_priors(bad)


def test_cli_refuses_a_bad_priors_file(tmp_path, capsys):
    from picopit.cli import main

    bad = tmp_path / "p.csv"
    bad.write_text("prior_id\nP1\n")
    assert main(["scenarios", "--priors", str(bad), "--out", str(tmp_path), "--no-progress"]) == 2
    assert "missing column" in capsys.readouterr().err


def test_cli_small_run(tmp_path, monkeypatch):
    """A small run on the main job's set-up, which has no torch."""
    import sys

    from picopit.cli import main

    monkeypatch.setitem(sys.modules, "torch", None)  # `import torch` raises ModuleNotFoundError
    monkeypatch.delitem(sys.modules, "picopit.surrogate_nn", raising=False)

    assert main(["scenarios", "--n", "30", "--keep", "20", "--seed", "5", "--out", str(tmp_path),
                 "--no-progress", "--no-figures"]) == 0
    m = json.loads((tmp_path / "scenarios.manifest.json").read_text())
    assert m["seed"] == 5 and m["sha256"] == S.sha256_file(tmp_path / "scenarios.jsonl")
    assert len(_core.load_scenarios(str(tmp_path / "scenarios.jsonl"))) == m["counts"]["retained"]
