"""``picopit oracle --grid-plot``: the whole grid of single shoves on a scene, drawn, with a
run's first contact marked. The map is the bound's own search laid out: its first success is
the shove the bound reports."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from picopit import _core, cli, oracle, oracle_grid

ROOT = Path(__file__).resolve().parents[1]
TEXTBOOK = ROOT / "data" / "textbook" / "scenarios.jsonl"
COARSE = '{"shoves": [0.5, 1.0, 1.5, 2.0, 2.5], "time_step": 0.25}'


def _scene(sid: str):
    return oracle.select(_core.load_scenarios(str(TEXTBOOK)), ids=[sid])[0]


def test_the_map_holds_the_shove_the_bound_finds_first():
    """The bound searches time by time, size by size, side by side and stops at the first
    success; the map simulates every cell: its first success in that order is the bound's."""
    sc = _scene("sc-00002")
    settings = oracle.resolve_settings(COARSE, tiers=False)
    m = oracle_grid.shove_map(sc, settings)
    bound = _core.ideal_pit(json.dumps(dict(sc)), json.dumps(settings))
    assert bound["feasible"] and m.successes > 0
    assert m.success.shape == (len(m.times), 2, 5) and m.times[0] >= m.t_reach - 1e-9
    assert np.allclose(np.diff(m.times), 0.25)
    first = next((t, v, s) for it, t in enumerate(m.times) for iv, v in enumerate(m.shoves)
                 for js, s in enumerate(m.sides) if m.success[it, js, iv])
    shove = bound["shove"]
    assert first == pytest.approx((shove["time"], shove["dv"], shove["side"]))
    assert 1 <= m.widest_band() <= 5
    at = m.at(shove["time"], shove["side"])
    assert at is not None and at[m.shoves.index(shove["dv"])]


def test_a_map_of_zero_shoves_is_empty():
    m = oracle_grid.shove_map(_scene("sc-00002"), oracle.resolve_settings('{"shoves": [0.0], "time_step": 0.5}',
                                                                         tiers=False))
    assert m.successes == 0 and m.widest_band() == 0 and len(m.times) > 3


def test_grid_plot_draws_each_scene_and_marks_the_runs_contact(tmp_path, capsys):
    """--grid-run marks the configuration's first contact and names the sizes that succeed
    at that time on that side; a scene the run did not touch is drawn without a mark."""
    sc = _scene("sc-00002")
    settings = oracle.resolve_settings(COARSE, tiers=True)
    m = oracle_grid.shove_map(sc, settings)
    t = float(m.times[2])
    run = tmp_path / "episodes.csv"
    run.write_text("config,scenario,contact_at,impact_y,success,reversed_at\n"
                   f"picopinn,sc-00002,{t},-0.7,False,{t + 1.5}\n"
                   "picopinn,sc-00004,,,False,\n")
    out = tmp_path / "maps"
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00002,sc-00004", "--settings", COARSE,
                   "--grid-plot", str(out), "--grid-run", str(run)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert (out / "sc-00002_shoves.png").stat().st_size > 5000 and (out / "sc-00004_shoves.png").exists()
    lines = {ln.split(":")[0]: ln for ln in text.splitlines() if ln.startswith("sc-")}
    sizes = [f"{v:g}" for v, ok in zip(m.shoves, m.success[2, m.sides.index(-1.0)]) if ok]
    assert f"first contact at {t:.2f} s on the right (lost after reversal)" in lines["sc-00002"]
    assert f"sizes that succeed there: {', '.join(sizes) or 'none'} m/s" in lines["sc-00002"]
    assert f"{m.successes} of {m.success.size} shoves succeed" in lines["sc-00002"]
    assert "first contact" not in lines["sc-00004"]


@pytest.mark.parametrize("argv, words", [
    (["--ids", "sc-00002", "--grid-run", "x"], "--grid-run: only with --grid-plot"),
    (["--n", "21", "--grid-plot", "{tmp}"], "at most 20"),
    (["--ids", "sc-00002", "--grid-plot", "{tmp}", "--tiers"], "not with --tiers"),
    (["--ids", "sc-00002", "--grid-plot", "{tmp}", "--grid-run", "{tmp}/missing"], "no such run"),
    (["--ids", "sc-00002", "--grid-plot", "{file}"], "--grid-plot"),
    (["--ids", "sc-00002", "--grid-plot", "/proc/picopit-x"], "--grid-plot /proc/picopit-x"),
])
def test_grid_plot_refuses_bad_input_naming_it(tmp_path, capsys, argv, words):
    (tmp_path / "f.txt").write_text("x")
    argv = [a.replace("{tmp}", str(tmp_path)).replace("{file}", str(tmp_path / "f.txt")) for a in argv]
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err


def test_at_contact_judges_each_touched_scene_at_its_first_contact(tmp_path, capsys):
    """--at-contact RUN: the sizes at the candidate time nearest the run's first contact, from
    its side, are the map's column there; a contact before the bound's earliest arrival has no
    candidate time; an untouched scene is left out; the table counts them by stage."""
    settings = oracle.resolve_settings(COARSE, tiers=True)
    a, b = _scene("sc-00002"), _scene("sc-00004")
    ma = oracle_grid.shove_map(a, settings)
    side = 1.0 if ma.success[:, 0, :].any() else -1.0
    it = next(i for i in range(len(ma.times)) if ma.success[i, ma.sides.index(side)].any())
    t = float(ma.times[it]) + 0.05
    run = tmp_path / "episodes.csv"
    run.write_text("config,scenario,contact_at,impact_y,success,reversed_at\n"
                   f"picopinn,sc-00002,{t},{0.7 * side},True,{t + 2.0}\n"
                   f"picopinn,sc-00004,0.5,-0.7,False,\n"
                   "picopinn,sc-00005,,,False,\n")
    out = tmp_path / "at.json"
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--ids", "sc-00002,sc-00004,sc-00005", "--settings",
                   COARSE, "--at-contact", str(run), "--no-progress", "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "2 of 3 scenes touched by picopinn" in text
    doc = json.loads(out.read_text())
    rows = {r["id"]: r for r in doc["scenes"]}
    assert set(rows) == {"sc-00002", "sc-00004"}
    assert rows["sc-00002"]["time"] == pytest.approx(ma.times[it])
    assert rows["sc-00002"]["success"] == [bool(v) for v in ma.success[it, ma.sides.index(side)]]
    assert rows["sc-00004"]["time"] is None and rows["sc-00004"]["stage"] == "lost in the push"
    summary = {s["stage"]: s for s in doc["summary"]}
    assert summary["success"]["scenes"] == 1 and summary["success"]["saving"] == 1
    assert summary["lost in the push"] == {**summary["lost in the push"], "scenes": 1, "on_grid": 0, "saving": 0}
    assert "| success | 1 | 1 | 1 |" in text and "| lost in the push | 1 | 0 | 0 | 0 |" in text


@pytest.mark.parametrize("argv, words", [
    (["--params", "half_scale", "--n", "4"], "--params half_scale: none of the chosen scenes"),
    (["--ids", "sc-00002", "--at-contact", "{tmp}/missing"], "no such run"),
    (["--ids", "sc-00002", "--at-contact", "{tmp}", "--grid-plot", "{tmp}"], "not with --grid-plot"),
    (["--ids", "sc-00002", "--at-contact", "{tmp}", "--tiers"], "not with --tiers"),
])
def test_at_contact_and_params_refuse_bad_input_naming_it(tmp_path, capsys, argv, words):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    rc = cli.main(["oracle", "--scenarios", str(TEXTBOOK), "--no-progress", *argv])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err
