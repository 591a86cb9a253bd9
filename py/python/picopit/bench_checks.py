"""What ``picopit bench`` checks before it runs an episode, so that a run that cannot work
stops in seconds with one line (exit status 2) instead of reporting a table of errors:

* ``check_models``: every model file a configuration needs, for every parameter set among
  the scenes, exists, loads and *runs* (the core refuses a file whose network gives non-finite
  outputs on its own normalisation statistics), and was trained on that parameter set;
* ``check_ray``: a Ray address answers a TCP connection within ``RAY_CONNECT_TIMEOUT``
  seconds (``ray.init`` itself retries an unreachable address for minutes).
"""

from __future__ import annotations

import socket
from pathlib import Path
from typing import TYPE_CHECKING, Dict, List, Optional, Tuple

from . import _core

if TYPE_CHECKING:  # pragma: no cover
    from .bench import BenchConfig

#: Seconds to wait for a Ray head to accept a connection.
RAY_CONNECT_TIMEOUT = 10.0
#: Ports Ray listens on when an address names none: the GCS and the Ray client server.
RAY_GCS_PORT = 6379
RAY_CLIENT_PORT = 10001


class BenchError(ValueError):
    """A benchmark option or input that cannot be used; the message names it."""


def _error(message: str) -> Exception:
    return BenchError(message)


def model_files(cfg: "BenchConfig", params_sets: List[str]) -> List[Tuple[str, str, Path]]:
    """``(configuration, parameter set, file)`` of every surrogate the run will load."""
    out: List[Tuple[str, str, Path]] = []
    for name in cfg.configs:
        doc = _core.episode_config(cfg.episode_config(name))
        kinds = {doc["model"]} | ({doc["planner_model"]} if doc.get("planner_model") else set())
        for kind in sorted(k for k in kinds if k != "4dof"):
            for p in params_sets:
                given = doc.get("model_path") if kind == doc["model"] else None
                path = Path(given) if given else cfg.models / p / f"{kind}.safetensors"
                out.append((name, p, path))
    return out


def check_models(cfg: "BenchConfig", scenes: List[Dict]) -> None:
    """Load every model file the run needs for ``scenes`` (the run's, ``bench.load_scenes``);
    raises ``BenchError`` naming the configuration and the file when one is missing, refused
    by the core, or of another parameter set."""
    counts: Dict[str, int] = {}
    for sc in scenes:
        counts[sc["params"]] = counts.get(sc["params"], 0) + 1
    for name, p, path in model_files(cfg, sorted(counts)):
        where = f"--configs {name}: model {path}"
        if not path.is_file():
            raise _error(f"{where}: no such file ({counts[p]} {p} scenes need it)")
        try:
            model = _core.SurrogateModel(str(path))
        except (_core.ModelError, ValueError, OSError) as e:
            raise _error(f"{where}: {e}") from None
        trained = model.metadata.get("param_set", "")
        if trained != p:
            raise _error(f"{where}: trained on param_set {trained!r}, but {counts[p]} of the scenes run {p!r}")


def ray_endpoint(address: str) -> Optional[Tuple[str, int]]:
    """The (host, port) a Ray address connects to, or None for ``local`` and ``auto`` (no
    remote head to reach)."""
    a = address.strip()
    if a in ("local", "auto", ""):
        return None
    port = RAY_GCS_PORT
    if a.startswith("ray://"):
        a, port = a[len("ray://"):], RAY_CLIENT_PORT
    a = a.split("/", 1)[0]
    host, sep, tail = a.rpartition(":")
    if sep and tail.isdigit() and not host.endswith(":"):
        a, port = host, int(tail)
    return a.strip("[]"), port


def check_ray(address: Optional[str], timeout: float = RAY_CONNECT_TIMEOUT) -> None:
    """Raise ``BenchError`` if the Ray head at ``address`` does not accept a TCP connection
    within ``timeout`` seconds."""
    if not address:
        return
    end = ray_endpoint(address)
    if end is None:
        return
    host, port = end
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except socket.timeout:
        raise _error(f"--ray-address {address}: no answer from {host}:{port} within {timeout:g} s") from None
    except OSError as e:
        raise _error(f"--ray-address {address}: cannot connect to {host}:{port}: {e.strerror or e}") from None


def finite_or_none(row: Dict) -> Dict:
    """The row with every non-finite float replaced by None (null in Parquet and JSON, empty
    in CSV), so that NaN never stands in a results table as if it were a number."""
    import math

    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}

