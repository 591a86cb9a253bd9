"""How close a benchmark run comes to the ideal-PIT bound (``picopit headroom``).

The bound (``picopit oracle --json``) says, scene by scene, whether one perfectly placed
shove could save it; a benchmark run (``picopit bench``) says which scenes each
configuration saved. Put side by side they give the controller's share of what a PIT could
save at all, overall and by parameter set, road category, adhesion band and target driver,
and the scenes it saves that no single shove does (a sustained push is not a shove). With a
``picopit bench`` run (whose episodes carry the funnel's columns) it also says where the
scenes a shove could save are lost: the funnel of :mod:`picopit.funnel` over those scenes
only, by stage, cause and who failed.

Only the scenes both the bound and every chosen configuration ran are counted, so that the
columns compare the same scenes; scenes the oracle could not judge (an ``error``) and
episodes that errored are left out.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

#: Scene attributes of the bound file the table is broken down by, in this order.
GROUPS = ("params", "category", "adhesion", "driver")

#: The episodes' columns the funnel of the savable scenes reads (every bench run has them).
FUNNEL_COLUMNS = ("config", "scenario", "success", "contacts", "reversed_at", "decided_at", "cause",
                  "failed_vehicle")


class HeadroomError(ValueError):
    """A bound file or selection that cannot be used (the message names the field)."""


@dataclass(frozen=True)
class Scene:
    feasible: bool
    params: str
    category: str
    adhesion: str
    driver: str


@dataclass(frozen=True)
class Row:
    """One group of scenes: how many, how many a shove could save, and per configuration
    the successes among those (``saved``) and among the others (``beyond``)."""

    group: str
    scenes: int
    feasible: int
    saved: Dict[str, int]
    beyond: Dict[str, int]

    def as_dict(self) -> Dict[str, object]:
        return asdict(self)


def read_bound(path: Path) -> Dict[str, Scene]:
    """``{scene id: Scene}`` of a ``picopit oracle --json`` file."""
    if not path.is_file():
        raise HeadroomError(f"{path}: no such bound file (write one with picopit oracle --json)")
    try:
        doc = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise HeadroomError(f"{path}: not a JSON file ({e})") from e
    scenes = doc.get("scenes") if isinstance(doc, dict) else None
    if not isinstance(scenes, list):
        raise HeadroomError(f"{path}: no `scenes` list (is this a picopit oracle --json file?)")
    out: Dict[str, Scene] = {}
    for i, s in enumerate(scenes):
        where = f"{path}: scenes[{i}]"
        if not isinstance(s, dict) or not isinstance(s.get("id"), str):
            raise HeadroomError(f"{where}: no scene `id`")
        if s.get("error"):
            continue
        result = s.get("result")
        feasible = result.get("feasible") if isinstance(result, dict) else None
        if not isinstance(feasible, bool):
            raise HeadroomError(f"{where} ({s['id']}): `result.feasible` is {feasible!r}, not true or false")
        attrs = {}
        for g in GROUPS:
            v = s.get(g)
            if not isinstance(v, str):
                raise HeadroomError(f"{where} ({s['id']}): `{g}` is {v!r}, not a name")
            attrs[g] = v
        if s["id"] in out:
            raise HeadroomError(f"{where}: scene {s['id']} appears twice")
        out[s["id"]] = Scene(feasible, **attrs)
    if not out:
        raise HeadroomError(f"{path}: no judged scenes")
    return out


def _selection(bound: Mapping[str, Scene], keys: Iterable[Tuple[str, str]],
               configs: Optional[Sequence[str]], params: Optional[str]) -> Tuple[List[str], List[str]]:
    """The chosen configurations and the scenes the bound and every one of them ran."""
    keys = set(keys)
    ran = sorted({c for c, _ in keys})
    if configs:
        unknown = [c for c in configs if c not in ran]
        if unknown:
            raise HeadroomError(f"--configs: {unknown[0]} is not in the run (it ran: {', '.join(ran) or 'none'})")
        chosen = list(dict.fromkeys(configs))
    else:
        chosen = ran
    ids = set(bound)
    if params is not None:
        known = sorted({s.params for s in bound.values()})
        if params not in known:
            raise HeadroomError(f"--params: {params} is not in the bound (it has: {', '.join(known)})")
        ids = {i for i in ids if bound[i].params == params}
    for c in chosen:
        ids &= {s for cc, s in keys if cc == c}
    if not ids:
        raise HeadroomError("the bound and the run have no scene in common")
    return chosen, sorted(ids)


def headroom(bound: Mapping[str, Scene], episodes: Mapping[Tuple[str, str], bool],
             configs: Optional[Sequence[str]] = None, params: Optional[str] = None) -> List[Row]:
    """The rows: all scenes, then one per value of each attribute in :data:`GROUPS` (in
    sorted order), over the scenes the bound and every configuration have."""
    chosen, members = _selection(bound, episodes, configs, params)

    def row(name: str, members: Sequence[str]) -> Row:
        feas = [i for i in members if bound[i].feasible]
        rest = [i for i in members if not bound[i].feasible]
        return Row(name, len(members), len(feas),
                   {c: sum(episodes[(c, i)] for i in feas) for c in chosen},
                   {c: sum(episodes[(c, i)] for i in rest) for c in chosen})

    rows = [row("all", members)]
    for g in GROUPS:
        for v in sorted({getattr(bound[i], g) for i in members}):
            rows.append(row(f"{g} {v}", [i for i in members if getattr(bound[i], g) == v]))
    return rows


def _number(v: object) -> Optional[float]:
    """A CSV cell or Parquet value as a number (``None`` for an empty cell)."""
    if v is None or v == "":
        return None
    return float(v)  # type: ignore[arg-type]


def lost(bound: Mapping[str, Scene], rows: Sequence[Mapping[str, object]],
         configs: Optional[Sequence[str]] = None, params: Optional[str] = None,
         source: str = "episodes") -> Dict[str, Dict[str, object]]:
    """Where the scenes a shove could save are lost: per configuration, the funnel
    (:func:`picopit.funnel.funnel`) of its episodes on the scenes the bound calls feasible
    (of those the bound and every chosen configuration ran). ``rows`` are a bench run's
    episodes (:data:`FUNNEL_COLUMNS`; CSV strings are read as numbers), ``source`` names
    them in errors."""
    from .compare import _truth
    from .funnel import funnel

    by_key: Dict[Tuple[str, str], Dict[str, object]] = {}
    for i, r in enumerate(rows, start=1):
        if r.get("error"):
            continue
        ep: Dict[str, object] = {**r, "error": None, "success": _truth(r["success"], Path(source), i)}
        for col in ("contacts", "reversed_at", "decided_at"):
            try:
                ep[col] = _number(r.get(col))
            except (TypeError, ValueError):
                raise HeadroomError(f"{source}: row {i}: `{col}` is {r.get(col)!r}, not a number") from None
        by_key[(str(r["config"]), str(r["scenario"]))] = ep
    chosen, members = _selection(bound, by_key, configs, params)
    feasible = [i for i in members if bound[i].feasible]
    return {c: funnel([by_key[(c, i)] for i in feasible]) for c in chosen}


def markdown(rows: Sequence[Row]) -> str:
    """The rows as a Markdown table: per configuration the successes among the scenes a
    shove could save (and their share), and those beyond the bound."""
    configs = list(rows[0].saved)
    head = "| group | scenes | a shove could save | " + " | ".join(
        f"{c}: saved of those | {c}: beyond" for c in configs) + " |"
    lines = [head, "|---|---|---|" + "---|---|" * len(configs)]
    for r in rows:
        cells = []
        for c in configs:
            share = f" ({100.0 * r.saved[c] / r.feasible:.1f} %)" if r.feasible else ""
            cells += [f"{r.saved[c]}{share}", f"{r.beyond[c]} of {r.scenes - r.feasible}"]
        lines.append(f"| {r.group} | {r.scenes} | {r.feasible} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
