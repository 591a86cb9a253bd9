"""picopit: automated Precision Immobilization Technique (PIT) on a Rust core.

The physics lives in Rust (``crates/dynamics``) and is reached through the extension module
``picopit._core``; this package adds the command line (``picopit``), scripted simulations and
plots. Units are SI throughout (m, s, kg, N, N m, rad).
"""

from __future__ import annotations

import sys
from typing import Any, Dict

from . import _core
from ._core import ModelError, ParamError, builtin_param_sets, footprint, load_params, wrap_angle

if sys.version_info >= (3, 11):
    import tomllib as _toml
else:  # pragma: no cover - exercised only on Python < 3.11
    import tomli as _toml

try:
    from importlib.metadata import PackageNotFoundError, version as _version

    __version__ = _version("picopit")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0+unknown"

__all__ = [
    "ModelError",
    "ParamError",
    "builtin_param_sets",
    "footprint",
    "load_params",
    "load_params_dict",
    "wrap_angle",
]

# The plant and the control models are bound as their Rust APIs land; re-export what exists.
for _name in ("Plant", "BulletModel", "FourDofTarget", "SurrogateModel", "CoupledMpc", "MpcError"):
    if hasattr(_core, _name):
        globals()[_name] = getattr(_core, _name)
        __all__.append(_name)


def load_params_dict(name_or_path: str) -> Dict[str, Any]:
    """A validated parameter set (built-in name or TOML path) as nested dicts.

    Raises :class:`ParamError` (a ``ValueError``) naming the offending field.
    """
    return _toml.loads(load_params(name_or_path))

# The scenario dataset (crates/sim): loader, validation and screening.
for _name in ("ScenarioError", "load_scenarios", "validate_scenario_line", "screen_scenario",
              "scenario_initial_states"):
    if hasattr(_core, _name):
        globals()[_name] = getattr(_core, _name)
        __all__.append(_name)

# The decision layer and the whole-maneuver controller (crates/planner).
for _name in ("PlannerError", "Planner", "PitController"):
    if hasattr(_core, _name):
        globals()[_name] = getattr(_core, _name)
        __all__.append(_name)

# The closed-loop episode runner (crates/sim::episode); the benchmark is picopit.bench.
for _name in ("EpisodeError", "run_episode", "episode_presets", "episode_config", "trajectory_columns"):
    if hasattr(_core, _name):
        globals()[_name] = getattr(_core, _name)
        __all__.append(_name)
