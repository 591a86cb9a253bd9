"""``picopit headroom``: a benchmark run set against the ideal-PIT bound, scene by scene, and
bad bound files refused in one line naming the field."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from test_compare import write_run

from picopit import cli, compare, headroom

ROOT = Path(__file__).resolve().parents[1]


def write_bound(path: Path, scenes) -> Path:
    """scenes: (id, feasible, params, category, adhesion, driver)."""
    doc = {"settings": {}, "summary": {}, "scenes": [
        {"id": i, "params": p, "category": c, "adhesion": a, "driver": d,
         "result": {"feasible": f}, "error": None}
        for i, f, p, c, a, d in scenes]}
    path.write_text(json.dumps(doc))
    return path


SCENES = [
    ("s0", True, "full_size", "curved", "high", "brake"),
    ("s1", True, "full_size", "curved", "low", "none"),
    ("s2", True, "full_size", "straight_urban", "high", "brake"),
    ("s3", False, "full_size", "straight_urban", "high", "none"),
    ("s4", False, "half_scale", "curved", "high", "none"),
]


def test_the_share_of_what_a_shove_could_save_by_group(tmp_path):
    bound = headroom.read_bound(write_bound(tmp_path / "b.json", SCENES))
    # picopinn saves s0, s2 (feasible) and s3 (beyond the bound); pinn saves s1 only. s5 is
    # not in the bound and s4 errored for pinn: neither is counted for either configuration.
    run = [("picopinn", "s0", True), ("picopinn", "s1", False), ("picopinn", "s2", True),
           ("picopinn", "s3", True), ("picopinn", "s4", True), ("picopinn", "s5", True),
           ("pinn", "s0", False), ("pinn", "s1", True), ("pinn", "s2", False), ("pinn", "s3", False),
           ("pinn", "s4", True, "episode failed")]
    eps = compare.read_episodes(compare.episodes_file(write_run(tmp_path / "run", run)))
    rows = {r.group: r for r in headroom.headroom(bound, eps)}
    a = rows["all"]
    assert (a.scenes, a.feasible, a.saved, a.beyond) == (4, 3, {"picopinn": 2, "pinn": 1}, {"picopinn": 1, "pinn": 0})
    assert "params half_scale" not in rows
    b = rows["driver brake"]
    assert (b.scenes, b.feasible, b.saved["picopinn"], b.saved["pinn"]) == (2, 2, 2, 0)
    low = rows["adhesion low"]
    assert (low.scenes, low.feasible, low.saved) == (1, 1, {"picopinn": 0, "pinn": 1})
    assert [r.group for r in headroom.headroom(bound, eps)][:3] == ["all", "params full_size", "category curved"]
    # One configuration only: its own scenes, s4 included; and a parameter set.
    only = {r.group: r for r in headroom.headroom(bound, eps, ["picopinn"])}
    assert (only["all"].scenes, only["all"].beyond) == (5, {"picopinn": 2})
    half = headroom.headroom(bound, eps, ["picopinn"], "half_scale")
    assert (half[0].scenes, half[0].feasible, half[0].beyond) == (1, 0, {"picopinn": 1})


def test_the_command_reads_what_picopit_oracle_writes(tmp_path, capsys):
    bound = tmp_path / "bound.json"
    scen = ROOT / "data" / "textbook" / "scenarios.jsonl"
    rc = cli.main(["oracle", "--scenarios", str(scen), "--n", "2", "--no-progress",
                   "--settings", '{"shoves": [2.0], "time_step": 0.5}', "--json", str(bound)])
    assert rc == 0, capsys.readouterr().err
    capsys.readouterr()
    ids = [s["id"] for s in json.loads(bound.read_text())["scenes"]]
    feasible = {s["id"]: s["result"]["feasible"] for s in json.loads(bound.read_text())["scenes"]}
    run = write_run(tmp_path / "run", [("4dof", ids[0], True), ("4dof", ids[1], False)])
    out = tmp_path / "h.json"
    assert cli.main(["headroom", str(bound), str(run), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    n_feas = sum(feasible.values())
    saved = int(feasible[ids[0]])
    assert f"| all | 2 | {n_feas} | {saved}" in text
    doc = json.loads(out.read_text())
    assert doc["rows"][0]["beyond"] == {"4dof": 1 - saved}


@pytest.mark.parametrize("edit, argv, message", [
    (lambda d: d.pop("scenes"), [], "no `scenes` list"),
    (lambda d: d["scenes"][1]["result"].pop("feasible"), [], "scenes[1] (s1): `result.feasible` is None"),
    (lambda d: d["scenes"][2].update(driver=3), [], "scenes[2] (s2): `driver` is 3, not a name"),
    (lambda d: d["scenes"].append(dict(d["scenes"][0])), [], "scene s0 appears twice"),
    (lambda d: None, ["--configs", "4dof"], "--configs: 4dof is not in the run"),
    (lambda d: None, ["--params", "tiny"], "--params: tiny is not in the bound"),
    (lambda d: [s.update(id="x" + s["id"]) for s in d["scenes"]], [], "no scene in common"),
])
def test_bad_input_is_one_line_naming_what_is_wrong(tmp_path, capsys, edit, argv, message):
    path = write_bound(tmp_path / "b.json", SCENES)
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))
    run = write_run(tmp_path / "run", [("picopinn", "s0", True), ("picopinn", "s1", False)])
    rc = cli.main(["headroom", str(path), str(run), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1, err


def test_a_missing_or_unreadable_bound_is_named(tmp_path, capsys):
    run = write_run(tmp_path / "run", [("picopinn", "s0", True)])
    assert cli.main(["headroom", str(tmp_path / "nope.json"), str(run)]) == 2
    assert "nope.json: no such bound file" in capsys.readouterr().err
    (tmp_path / "bad.json").write_text("{not json")
    assert cli.main(["headroom", str(tmp_path / "bad.json"), str(run)]) == 2
    assert "bad.json: not a JSON file" in capsys.readouterr().err


def write_bench_run(folder: Path, rows) -> Path:
    """An episodes.csv with the funnel's columns, as picopit bench writes them; rows:
    (config, scene, success, contacts, reversed_at, decided_at, cause, failed_vehicle)."""
    import csv

    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "episodes.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*headroom.FUNNEL_COLUMNS, "error"])
        for cfg, scene, ok, contacts, rev, dec, cause, vehicle in rows:
            w.writerow([cfg, scene, ok, contacts, "" if rev is None else rev, dec, cause, vehicle, ""])
    return folder


BENCH_RUN = [
    # s0 saved; s1 lost before contact; s2 reversed at 5 s, over the edge at 7 s; s3 (no
    # shove saves it) lost in the push: not in the funnel of the savable scenes.
    ("picopinn", "s0", True, 1, 4.0, 9.0, "", ""),
    ("picopinn", "s1", False, 0, None, 6.0, "decision_infeasible", ""),
    ("picopinn", "s2", False, 1, 5.0, 7.0, "boundary_violation", "target"),
    ("picopinn", "s3", False, 1, None, 6.5, "secondary_collision", "target"),
]


def test_where_the_scenes_a_shove_could_save_are_lost(tmp_path):
    bound = headroom.read_bound(write_bound(tmp_path / "b.json", SCENES))
    run = compare.episodes_file(write_bench_run(tmp_path / "run", BENCH_RUN))
    f = headroom.lost(bound, compare.read_rows(run), params="full_size")["picopinn"]
    assert (f["scenes"], f["first_contact"], f["reversed"], f["success"]) == (3, 2, 2, 1)
    assert f["lost"] == {"before_contact": {"decision_infeasible": {"controller": 1}},
                         "in_push": {},
                         "after_reversal": {"boundary_violation": {"target": 1}}}


def test_the_command_prints_the_funnel_of_the_savable_scenes_for_a_bench_run(tmp_path, capsys):
    path = write_bound(tmp_path / "b.json", SCENES)
    out = tmp_path / "h.json"
    rc = cli.main(["headroom", str(path), str(write_bench_run(tmp_path / "run", BENCH_RUN)), "--json", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "| picopinn | 3 | 2 | 2 | 1 | 1 | 0 | 1 |" in text
    assert json.loads(out.read_text())["lost"]["picopinn"]["success"] == 1
    # A run without the funnel's columns gets the headroom table alone.
    run = write_run(tmp_path / "plain", [("picopinn", "s0", True), ("picopinn", "s1", False)])
    assert cli.main(["headroom", str(path), str(run)]) == 0
    assert "Where the scenes" not in capsys.readouterr().out
    # A malformed cell is one line naming the row and the column.
    bad = [("picopinn", "s0", True, "many", 4.0, 9.0, "", "")]
    assert cli.main(["headroom", str(path), str(write_bench_run(tmp_path / "bad", bad))]) == 2
    err = capsys.readouterr().err
    assert "row 1: `contacts` is 'many', not a number" in err and err.count("\n") == 1, err
