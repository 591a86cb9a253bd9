"""What a ``picopit trials`` run is: the binaries and files it needs, found, and the runs it
plans.

* locating things: the source tree (``repo_root``), the release binaries ``pit-vehicle`` and
  ``pit-controller`` (``find_bin_dir``), the trial scenarios by id (``load_cases``,
  ``cfg_scenario``) and the ``--cases`` list (``parse_cases``);
* ``TrialsConfig`` (the validated options), ``Trial`` (one run: case, nominal or repeat,
  seed, noise, latency, recording) and ``plan`` (per case the nominal run, then the repeats);
* ``TrialsError`` and ``ERROR_CAUSE``, shared by the runner, the rows and the report.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

VEHICLE_BIN = "pit-vehicle"
CONTROLLER_BIN = "pit-controller"
HALF_SCALE_SCENARIOS = Path("data/trials/half_scale.jsonl")
HALF_SCALE_CONTROLLER = Path("configs/controller_half_scale.toml")
BUILD_HINT = "run ./scripts/setup.sh --full or `cargo build --release -p picopit-vehicle-io --bins`"
ERROR_CAUSE = "error"


class TrialsError(ValueError):
    """An option or input of ``picopit trials`` that cannot be used; the message names it."""


# --- locating things ----------------------------------------------------------------------


def _walk_up(start: Path) -> Iterable[Path]:
    start = start.resolve()
    yield start
    yield from start.parents


def repo_root(start: Optional[Path] = None) -> Optional[Path]:
    """The source tree (a folder with ``Cargo.toml`` and ``data/trials``), walking up from
    ``start`` (default: the current directory, then this package's location)."""
    starts = [start] if start is not None else [Path.cwd(), Path(__file__).parent]
    for s in starts:
        for d in _walk_up(s):
            if (d / "Cargo.toml").is_file() and (d / "data" / "trials").is_dir():
                return d
    return None


def find_bin_dir(bin_dir: Optional[str] = None, env: Optional[Mapping[str, str]] = None) -> Path:
    """The folder holding ``pit-vehicle`` and ``pit-controller``: ``bin_dir``, else
    ``$PICOPIT_BIN_DIR``, else ``<repo>/target/release`` found by walking up from the current
    directory and from this package. Raises ``TrialsError`` naming what is missing."""
    env = os.environ if env is None else env
    if bin_dir:
        candidates, source = [Path(bin_dir)], "--bin-dir"
    elif env.get("PICOPIT_BIN_DIR"):
        candidates, source = [Path(env["PICOPIT_BIN_DIR"])], "PICOPIT_BIN_DIR"
    else:
        candidates, source = [], "target/release"
        for s in (Path.cwd(), Path(__file__).parent):
            for d in _walk_up(s):
                if (d / "Cargo.toml").is_file() and d / "target" / "release" not in candidates:
                    candidates.append(d / "target" / "release")
        if not candidates:
            raise TrialsError(f"no source tree with target/release above {Path.cwd()} or the package; "
                              f"give --bin-dir or PICOPIT_BIN_DIR, or {BUILD_HINT}")
    for c in candidates:
        if all(os.access(c / b, os.X_OK) and (c / b).is_file() for b in (VEHICLE_BIN, CONTROLLER_BIN)):
            return c.resolve()
    c = candidates[0]
    missing = [b for b in (VEHICLE_BIN, CONTROLLER_BIN) if not (c / b).is_file()]
    what = " and ".join(missing) if missing else f"{VEHICLE_BIN}/{CONTROLLER_BIN} (not executable)"
    raise TrialsError(f"{what} not found in {c} ({source}): {BUILD_HINT}")


def load_cases(path: Path) -> Dict[str, Dict[str, Any]]:
    """The scenarios of a JSON-lines file by id (file order)."""
    if not path.is_file():
        raise TrialsError(f"--scenarios: {path} does not exist")
    cases: Dict[str, Dict[str, Any]] = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            sc = json.loads(line)
            cases[str(sc["id"])] = sc
        except (ValueError, KeyError, TypeError) as e:
            raise TrialsError(f"--scenarios: {path} line {n}: not a scenario ({e})") from None
    if not cases:
        raise TrialsError(f"--scenarios: {path} holds no scenario")
    return cases


def parse_cases(text: Optional[str], known: Sequence[str]) -> List[str]:
    """The case ids of ``--cases`` (all of ``known`` when the option is not given; an empty
    list is an error, not "all")."""
    if text is None:
        return list(known)
    ids = [c.strip() for c in text.split(",") if c.strip()]
    if not ids:
        raise TrialsError("--cases: no case given; known: " + ",".join(known))
    for c in ids:
        if c not in known:
            raise TrialsError(f"--cases: unknown case {c!r}; known: {','.join(known)}")
    if len(set(ids)) != len(ids):
        raise TrialsError(f"--cases: a case is repeated: {text}")
    return ids


# --- configuration ------------------------------------------------------------------------


@dataclass
class TrialsConfig:
    scenarios: Path
    controller_config: Optional[Path]  # None: the controller's built-in (full-size) settings
    bin_dir: Path
    cases: List[str]
    repeats: int = 5
    noise: str = "paper"
    latency: float = 0.05
    realtime: bool = False
    jobs: int = 1
    timeout: Optional[float] = None  # wall seconds per run; None: from the scenario's T_max
    model: Optional[str] = None
    #: the controller predicts the states over their age (pit-controller's default)
    delay_compensation: bool = True
    cwd: Path = field(default_factory=Path.cwd)  # the controller finds models/ from here
    t_max: Dict[str, float] = field(default_factory=dict)

    def validate(self) -> "TrialsConfig":
        if self.repeats < 0:
            raise TrialsError(f"--repeats = {self.repeats}: must be >= 0")
        if self.jobs < 1:
            raise TrialsError(f"--jobs = {self.jobs}: must be >= 1")
        if not (self.latency >= 0 and math.isfinite(self.latency)):
            raise TrialsError(f"--latency = {self.latency}: must be a finite number >= 0 (s)")
        if self.noise not in ("none", "paper"):
            raise TrialsError(f"--noise = {self.noise!r}: none or paper")
        if self.timeout is not None and not self.timeout > 0:
            raise TrialsError(f"--timeout = {self.timeout}: must be > 0 (s)")
        if self.controller_config is not None and not self.controller_config.is_file():
            raise TrialsError(f"--controller-config: {self.controller_config} does not exist")
        return self

    def run_timeout(self, case: str) -> float:
        if self.timeout is not None:
            return self.timeout
        t_max = self.t_max.get(case, 10.0)
        # Lock step runs far faster than real time; the margin covers a loaded machine.
        return (t_max + 20.0) * 1.5 + 30.0 if self.realtime else 120.0 + 4.0 * t_max


@dataclass
class Trial:
    case: str
    kind: str  # "nominal" or "repeat"
    seed: int
    noise: str
    latency: float
    record: bool
    index: int = 0  # unique within the run (service prefix)

    @property
    def name(self) -> str:
        return "nominal" if self.kind == "nominal" else f"seed-{self.seed}"


def plan(cfg: TrialsConfig) -> List[Trial]:
    """The runs: per case the nominal run, then the noisy repeats (seeds 1..K)."""
    trials: List[Trial] = []
    for c in cfg.cases:
        trials.append(Trial(c, "nominal", 0, "none", 0.0, True))
        for s in range(1, cfg.repeats + 1):
            trials.append(Trial(c, "repeat", s, cfg.noise, cfg.latency, False))
    for i, t in enumerate(trials):
        t.index = i
    return trials


_SCEN: Dict[Tuple[str, str], Dict[str, Any]] = {}


def cfg_scenario(cfg: TrialsConfig, case: str) -> Dict[str, Any]:
    key = (str(cfg.scenarios), case)
    if key not in _SCEN:
        _SCEN.update({(str(cfg.scenarios), k): v for k, v in load_cases(cfg.scenarios).items()})
    return _SCEN.get(key, {})
