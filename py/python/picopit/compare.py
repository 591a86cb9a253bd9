"""Two benchmark runs compared scene by scene (``picopit compare``).

A change to the controller is judged by what it does to the same scenes: each run's
``episodes.parquet`` (or ``episodes.csv``) is read, the episodes are paired by configuration
and scene id (the scenes both runs ran), and for every configuration the table gives the
successes of each run, the scenes only one of them saved and the two-sided exact McNemar
p-value of that split; a pooled row sums the configurations (each pair of episodes is one
trial). A split with p above ~0.05 is within what the scenes' luck makes of two equal
controllers. Episodes with an ``error`` are left out of the pairing.

Where both runs have the funnel's columns (``contacts``, ``reversed_at``, ``decided_at``, as
``picopit bench`` writes them), the scenes whose outcome moved are also counted by the funnel
stage they ended in under each run (success, or lost before contact, in the push or after
reversal; :mod:`picopit.funnel`): a change that trades pushes gone wrong for reversed targets
lost afterwards shows as such even when its successes are level.
"""

from __future__ import annotations

import csv
import math
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from .bench_summary import mcnemar_exact_p
from .funnel import LOSSES, stage_lost

#: Columns the comparison reads.
COLUMNS = ("config", "scenario", "success")
#: Columns the stage moves need besides ``COLUMNS`` (a run without them has no moves).
STAGE_COLUMNS = ("contacts", "reversed_at", "decided_at")
#: The stage an episode ended in, in the funnel's order.
STAGES = ("success", *LOSSES)


class CompareError(ValueError):
    """A run that cannot be read or compared (the message names the path or column)."""


@dataclass(frozen=True)
class Row:
    """One configuration (or the pooled row, ``config == "pooled"``)."""

    config: str
    scenes: int
    success_a: int
    success_b: int
    only_a: int
    only_b: int

    @property
    def mcnemar_p(self) -> float:
        return mcnemar_exact_p(self.only_a, self.only_b)

    def as_dict(self) -> Dict[str, object]:
        return {**asdict(self), "mcnemar_p": self.mcnemar_p}


def episodes_file(run: Path) -> Path:
    """The episodes file of a run folder (Parquet before CSV), or ``run`` itself if a file."""
    if run.is_file():
        return run
    if run.is_dir():
        for name in ("episodes.parquet", "episodes.csv"):
            if (run / name).is_file():
                return run / name
        raise CompareError(f"{run}: no episodes.parquet or episodes.csv in this run folder")
    raise CompareError(f"{run}: no such run folder or file")


def _truth(v: object, path: Path, line: int) -> bool:
    if isinstance(v, bool):
        return v
    s = str(v).strip().lower()
    if s in ("true", "1"):
        return True
    if s in ("false", "0"):
        return False
    raise CompareError(f"{path}: row {line}: `success` is {v!r}, not true or false")


def read_rows(path: Path, columns: Sequence[str] = COLUMNS) -> List[Mapping[str, object]]:
    """The rows of one run's episodes file (Parquet or CSV; CSV values are strings), after
    checking that it has ``columns``."""
    if path.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq
        except ImportError as e:  # pragma: no cover - pyarrow is a dependency of bench
            raise CompareError(f"{path}: reading Parquet needs pyarrow ({e})") from e
        try:
            table = pq.read_table(path)
        except Exception as e:  # noqa: BLE001 - any unreadable file is bad input here
            raise CompareError(f"{path}: not a readable Parquet file ({e})") from e
        names = set(table.column_names)
        rows: List[Mapping[str, object]] = table.to_pylist()
    else:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            names = set(reader.fieldnames or ())
            rows = list(reader)
    missing = [c for c in columns if c not in names]
    if missing:
        raise CompareError(f"{path}: no `{missing[0]}` column (need {', '.join(columns)})")
    return rows


def read_episodes(path: Path) -> Dict[Tuple[str, str], bool]:
    """``{(config, scenario): success}`` of one run's episodes file."""
    return episodes_of(read_rows(path), path)


def episodes_of(rows: Sequence[Mapping[str, object]], path: Path) -> Dict[Tuple[str, str], bool]:
    """``{(config, scenario): success}`` of rows read from ``path`` (:func:`read_rows`);
    errored episodes are left out, a scene twice in one configuration is refused."""
    out: Dict[Tuple[str, str], bool] = {}
    for i, r in enumerate(rows, start=1):
        if r.get("error"):
            continue
        key = (str(r["config"]), str(r["scenario"]))
        if key in out:
            raise CompareError(f"{path}: row {i}: scene {key[1]} appears twice for {key[0]}")
        out[key] = _truth(r["success"], path, i)
    return out


def _number(v: object, column: str, path: Path, line: int) -> Optional[float]:
    """A CSV or Parquet cell as a number (``None`` when empty or null)."""
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    try:
        x = float(v)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CompareError(f"{path}: row {line}: `{column}` is {v!r}, not a number") from None
    return None if math.isnan(x) else x


def stages_of(rows: Sequence[Mapping[str, object]], path: Path) -> Optional[Dict[Tuple[str, str], str]]:
    """``{(config, scenario): stage}`` (one of :data:`STAGES`) of rows read from ``path``,
    errored episodes left out; ``None`` when the rows lack :data:`STAGE_COLUMNS`."""
    if rows and any(c not in rows[0] for c in STAGE_COLUMNS):
        return None
    out: Dict[Tuple[str, str], str] = {}
    for i, r in enumerate(rows, start=1):
        if r.get("error"):
            continue
        typed = {
            "success": _truth(r["success"], path, i),
            "contacts": _number(r["contacts"], "contacts", path, i) or 0,
            "reversed_at": _number(r["reversed_at"], "reversed_at", path, i),
            "decided_at": _number(r["decided_at"], "decided_at", path, i),
        }
        out[(str(r["config"]), str(r["scenario"]))] = stage_lost(typed) or "success"
    return out


def moves(a: Mapping[Tuple[str, str], str], b: Mapping[Tuple[str, str], str],
          configs: Sequence[str]) -> Dict[str, List[Tuple[str, str, int]]]:
    """Per configuration, the scenes both runs ran whose stage differs, counted by
    ``(stage in A, stage in B)``, most frequent first."""
    counts: Dict[str, Counter] = {cfg: Counter() for cfg in configs}
    for key, sa in a.items():
        sb = b.get(key)
        if key[0] in counts and sb is not None and sb != sa:
            counts[key[0]][(sa, sb)] += 1
    rank = {s: i for i, s in enumerate(STAGES)}
    return {cfg: [(sa, sb, n) for (sa, sb), n in
                  sorted(c.items(), key=lambda kv: (-kv[1], rank[kv[0][0]], rank[kv[0][1]]))]
            for cfg, c in counts.items()}


def markdown_moves(moved: Mapping[str, Sequence[Tuple[str, str, int]]]) -> str:
    """The stage moves as a Markdown table (empty when no scene moved)."""
    if not any(moved.values()):
        return ""
    lines = ["", "Scenes whose outcome moved, by the stage each run ended them in:", "",
             "| config | A | B | scenes |", "|---|---|---|---|"]
    for cfg, rows in moved.items():
        for sa, sb, n in rows:
            lines.append(f"| {cfg} | {sa.replace('_', ' ')} | {sb.replace('_', ' ')} | {n} |")
    return "\n".join(lines) + "\n"


def compare(a: Mapping[Tuple[str, str], bool], b: Mapping[Tuple[str, str], bool],
            configs: Optional[Sequence[str]] = None) -> List[Row]:
    """One row per configuration both runs ran (in ``configs`` order if given), then the
    pooled row when there is more than one."""
    common = sorted({c for c, _ in a} & {c for c, _ in b})
    if configs:
        unknown = [c for c in configs if c not in common]
        if unknown:
            raise CompareError(f"--configs: {unknown[0]} is not in both runs (both ran: {', '.join(common) or 'none'})")
        common = list(dict.fromkeys(configs))  # each once, in the order given
    rows: List[Row] = []
    for cfg in common:
        scenes = sorted({s for c, s in a if c == cfg} & {s for c, s in b if c == cfg})
        wa = [a[(cfg, s)] for s in scenes]
        wb = [b[(cfg, s)] for s in scenes]
        rows.append(Row(cfg, len(scenes), sum(wa), sum(wb),
                        sum(x and not y for x, y in zip(wa, wb)), sum(y and not x for x, y in zip(wa, wb))))
    if not rows or all(r.scenes == 0 for r in rows):
        raise CompareError("the two runs have no configuration and scene in common")
    if len(rows) > 1:
        rows.append(Row("pooled", *(sum(getattr(r, f) for r in rows)
                                    for f in ("scenes", "success_a", "success_b", "only_a", "only_b"))))
    return rows


def markdown(rows: Sequence[Row], name_a: str, name_b: str) -> str:
    """The comparison as a Markdown table (A and B named above it)."""
    lines = [f"A: {name_a}", f"B: {name_b}", "",
             "| config | scenes | success A | success B | only A | only B | exact McNemar p |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        pa = 100.0 * r.success_a / r.scenes if r.scenes else 0.0
        pb = 100.0 * r.success_b / r.scenes if r.scenes else 0.0
        lines.append(f"| {r.config} | {r.scenes} | {r.success_a} ({pa:.1f} %) | {r.success_b} ({pb:.1f} %) "
                     f"| {r.only_a} | {r.only_b} | {r.mcnemar_p:.3g} |")
    return "\n".join(lines) + "\n"
