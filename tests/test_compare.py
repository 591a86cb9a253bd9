"""``picopit compare``: two benchmark runs paired scene by scene, the discordant scenes counted
and tested (exact McNemar), and bad runs refused in one line naming the file or column."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from picopit import bench_summary, cli, compare

FIELDS = ("config", "scenario", "success", "error")


def write_run(folder: Path, rows, name: str = "episodes.csv") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / name, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        for cfg, scene, ok, *err in rows:
            w.writerow({"config": cfg, "scenario": scene, "success": ok, "error": err[0] if err else ""})
    return folder


def test_the_discordant_scenes_are_counted_on_the_common_scenes_only(tmp_path):
    # picopinn: 7 shared scenes, A saves s0 only, B saves s1..s6 only; s7 only in A (not paired),
    # s8 errored in B (not paired). pinn: both save the same two scenes.
    a = [("picopinn", "s0", True)] + [("picopinn", f"s{i}", False) for i in range(1, 7)]
    a += [("picopinn", "s7", True), ("picopinn", "s8", True), ("pinn", "s0", True), ("pinn", "s1", True)]
    b = [("picopinn", "s0", False)] + [("picopinn", f"s{i}", True) for i in range(1, 7)]
    b += [("picopinn", "s8", False, "episode failed"), ("pinn", "s0", True), ("pinn", "s1", True)]
    ea = compare.read_episodes(compare.episodes_file(write_run(tmp_path / "a", a)))
    eb = compare.read_episodes(compare.episodes_file(write_run(tmp_path / "b", b)))
    rows = {r.config: r for r in compare.compare(ea, eb)}
    p = rows["picopinn"]
    assert (p.scenes, p.success_a, p.success_b, p.only_a, p.only_b) == (7, 1, 6, 1, 6)
    # Two-sided exact binomial: 2 · (C(7,0) + C(7,1)) / 2⁷.
    assert math.isclose(p.mcnemar_p, 2 * (1 + 7) / 2**7)
    q = rows["pinn"]
    assert (q.scenes, q.only_a, q.only_b, q.mcnemar_p) == (2, 0, 0, 1.0)
    pooled = rows["pooled"]
    assert (pooled.scenes, pooled.success_a, pooled.success_b, pooled.only_a, pooled.only_b) == (9, 3, 8, 1, 6)


def test_a_parquet_run_reads_as_its_csv(tmp_path):
    pytest.importorskip("pyarrow")
    rows = [{"config": "picopinn", "scenario": f"s{i}", "success": i % 3 == 0} for i in range(9)]
    table = [{k: r.get(k) for k in bench_summary.EPISODE_FIELDS} for r in rows]
    (tmp_path / "pq").mkdir()
    path, note = bench_summary.write_episodes(table, tmp_path / "pq")
    assert note is None and path.suffix == ".parquet"
    assert compare.episodes_file(tmp_path / "pq") == path
    write_run(tmp_path / "csv", [(r["config"], r["scenario"], r["success"]) for r in rows])
    from_pq = compare.read_episodes(path)
    assert from_pq == compare.read_episodes(tmp_path / "csv" / "episodes.csv")
    assert sum(from_pq.values()) == 3


def test_the_command_prints_the_table_and_writes_json(tmp_path, capsys):
    a = write_run(tmp_path / "a", [("4dof", "s0", True), ("4dof", "s1", False), ("pinn", "s0", False)])
    b = write_run(tmp_path / "b", [("4dof", "s0", True), ("4dof", "s1", True), ("pinn", "s0", True)])
    out = tmp_path / "cmp.json"
    rc = cli.main(["compare", str(a), str(b), "--configs", "4dof", "--json", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "| 4dof | 2 | 1 (50.0 %) | 2 (100.0 %) | 0 | 1 | 1 |" in text
    assert "pinn" not in text.split("|---|")[-1]
    doc = json.loads(out.read_text())
    assert [r["config"] for r in doc["rows"]] == ["4dof"]
    assert doc["rows"][0]["only_b"] == 1


@pytest.mark.parametrize("rows_b, argv, message", [
    ([("picopinn", "s0", "maybe")], [], "row 1: `success` is 'maybe'"),
    ([("picopinn", "s0", True), ("picopinn", "s0", False)], [], "scene s0 appears twice for picopinn"),
    ([("pinn", "s9", True)], [], "no configuration and scene in common"),
    ([("picopinn", "s0", True)], ["--configs", "4dof"], "--configs: 4dof is not in both runs"),
])
def test_bad_runs_are_one_line_naming_what_is_wrong(tmp_path, capsys, rows_b, argv, message):
    a = write_run(tmp_path / "a", [("picopinn", "s0", True)])
    b = write_run(tmp_path / "b", rows_b)
    rc = cli.main(["compare", str(a), str(b), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1, err


def test_a_missing_run_or_column_is_named(tmp_path, capsys):
    a = write_run(tmp_path / "a", [("picopinn", "s0", True)])
    assert cli.main(["compare", str(a), str(tmp_path / "nope")]) == 2
    assert "nope: no such run folder or file" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert cli.main(["compare", str(a), str(tmp_path / "empty")]) == 2
    assert "no episodes.parquet or episodes.csv" in capsys.readouterr().err
    (tmp_path / "bad.csv").write_text("config,scene,success\npicopinn,s0,true\n")
    assert cli.main(["compare", str(a), str(tmp_path / "bad.csv")]) == 2
    assert "no `scenario` column" in capsys.readouterr().err


STAGE_FIELDS = ("config", "scenario", "success", "error", "contacts", "reversed_at", "decided_at")

# (success, contacts, reversed_at, decided_at) of an episode ending in each stage.
ENDS = {
    "success": ("true", "1", "4.0", "7.0"),
    "before_contact": ("false", "0", "", "3.0"),
    "in_push": ("false", "1", "", "5.0"),
    "after_reversal": ("false", "1", "4.5", "6.0"),
    # Reversed only after the failure was decided: lost in the push (the funnel's rule).
    "late_reversal": ("false", "1", "6.5", "6.0"),
}


def write_stage_run(folder: Path, ends) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / "episodes.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=STAGE_FIELDS)
        w.writeheader()
        for i, end in enumerate(ends):
            ok, contacts, rev, dec = ENDS[end]
            w.writerow({"config": "picopinn", "scenario": f"s{i}", "success": ok, "error": "",
                        "contacts": contacts, "reversed_at": rev, "decided_at": dec})
    return folder


def test_the_scenes_that_moved_are_counted_by_the_stage_each_run_ended_them_in(tmp_path, capsys):
    a = write_stage_run(tmp_path / "a", ["in_push", "in_push", "success", "before_contact",
                                         "after_reversal", "late_reversal", "success"])
    b = write_stage_run(tmp_path / "b", ["after_reversal", "after_reversal", "in_push", "success",
                                         "after_reversal", "success", "success"])
    out = tmp_path / "cmp.json"
    assert cli.main(["compare", str(a), str(b), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| picopinn | in push | after reversal | 2 |" in text
    assert "| picopinn | success | in push | 1 |" in text
    assert "| picopinn | before contact | success | 1 |" in text
    # s5 reversed after its failure was decided: in the push in A.
    assert "| picopinn | in push | success | 1 |" in text
    # Unmoved scenes (s4 after reversal in both, s6 a success in both) are not rows.
    assert "after reversal | after reversal" not in text and "success | success" not in text
    moves = json.loads(out.read_text())["moves"]["picopinn"]
    assert moves[0] == {"a": "in_push", "b": "after_reversal", "scenes": 2}
    assert sum(m["scenes"] for m in moves) == 5


def test_runs_without_the_funnel_columns_have_no_moves_and_a_bad_cell_is_named(tmp_path, capsys):
    a = write_run(tmp_path / "a", [("picopinn", "s0", True)])
    b = write_run(tmp_path / "b", [("picopinn", "s0", False)])
    assert cli.main(["compare", str(a), str(b)]) == 0
    assert "moved" not in capsys.readouterr().out
    c = write_stage_run(tmp_path / "c", ["success"])
    text = (c / "episodes.csv").read_text().replace(",4.0,", ",soon,")
    (c / "episodes.csv").write_text(text)
    d = write_stage_run(tmp_path / "d", ["in_push"])
    assert cli.main(["compare", str(c), str(d)]) == 2
    err = capsys.readouterr().err
    assert "row 1: `reversed_at` is 'soon', not a number" in err and err.count("\n") == 1, err
