"""Hostile input: every file a user hands picopit, mutated at random (seeded), must load or be
refused with the package's own error naming the line or field; never another exception, a
Rust panic or a NaN that passes for a result.

The mutations are of the kinds a fuzzer finds and a user makes: a value replaced by one of
another type or an absurd magnitude (NaN, ±inf, 1e308, −1, 0, a string, a list, a table), a
key deleted or misspelt, a line cut short, bytes flipped. Each file kind gets a few hundred
seeded cases, so a failure names its seed and repeats. Any other exception fails the test,
a Rust panic (pyo3's PanicException) included.
"""

from __future__ import annotations

import json
import math
import random
import re
from pathlib import Path

import numpy as np
import pytest

import picopit

REPO = Path(__file__).resolve().parents[1]
HOSTILE = [float("nan"), float("inf"), -float("inf"), 1e308, -1e308, -1.0, 0.0, 1e-300, 2**63, -(2**63),
           "x", "", [], [1, 2], {}, {"a": 1}, None, True]
TOML_HOSTILE = ["nan", "inf", "-inf", "1e308", "-1e308", "-1.0", "0", "1e-300", "9223372036854775807",
                '"x"', '""', "[]", "[1, 2]", "{}", "true"]

def leaves(obj, path=()):
    """Every (path, value) of a JSON object's scalars and containers, depth first."""
    yield path, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from leaves(v, path + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from leaves(v, path + (i,))


def set_at(obj, path, value):
    for k in path[:-1]:
        obj = obj[k]
    obj[path[-1]] = value


def del_at(obj, path):
    for k in path[:-1]:
        obj = obj[k]
    del obj[path[-1]]


# --- scenario JSONL ------------------------------------------------------------------------

SCENES = [l for l in (REPO / "data" / "scenarios.jsonl").read_text().splitlines()[:40:8]]


def mutate_scenario(rng: random.Random) -> tuple[str, str | None]:
    """A mutated scenario line and, for structural mutations, the key that was touched."""
    sc = json.loads(rng.choice(SCENES))
    paths = [p for p, _ in leaves(sc) if p]
    path = rng.choice(paths)
    kind = rng.randrange(4)
    key = str(path[-1]) if not isinstance(path[-1], int) else str(path[-2]) if len(path) > 1 else None
    if kind == 0:
        value = rng.choice(HOSTILE)
        set_at(sc, path, value)
        if isinstance(value, float) and not math.isfinite(value):
            key = None  # NaN and ±inf are not JSON: the text is refused as such, by column
    elif kind == 1 and not isinstance(path[-1], int):
        del_at(sc, path)
    elif kind == 2 and not isinstance(path[-1], int):
        parent = sc
        for k in path[:-1]:
            parent = parent[k]
        parent[str(path[-1]) + "_x"] = parent.pop(path[-1])
    else:
        text = json.dumps(sc, allow_nan=True)
        cut = rng.randrange(len(text))
        return (text[:cut] if rng.random() < 0.5 else text[:cut] + rng.choice("{}[],:\"0e-") + text[cut + 1:]), None
    return json.dumps(sc, allow_nan=True), key


@pytest.mark.parametrize("seed", range(300))
def test_scenario_lines(seed):
    rng = random.Random(seed)
    text, key = mutate_scenario(rng)
    try:
        sc = picopit.validate_scenario_line(text, 7)
    except picopit.ScenarioError as e:
        msg = str(e)
        assert msg.startswith("line 7: "), msg
        assert "\n" not in msg.strip(), msg
        if key is not None:
            assert key in msg, (seed, key, msg)
        return
    # Accepted: it must be usable, to finite numbers.
    states = picopit.scenario_initial_states(json.dumps(sc))
    assert np.all(np.isfinite(states["bullet"])) and np.all(np.isfinite(states["target"])), seed
    screened = picopit.screen_scenario(json.dumps(sc))
    assert screened["verdict"] in ("keep", "trivial", "impossible", "rejected")
    assert math.isfinite(screened["t_reach"]) or screened["t_reach"] == math.inf


def test_a_scenario_file_names_the_line(tmp_path):
    lines = SCENES[:3]
    bad = json.loads(lines[1])
    bad["mu"] = "slippery"
    (tmp_path / "s.jsonl").write_text("\n".join([lines[0], json.dumps(bad), lines[2]]) + "\n")
    with pytest.raises(picopit.ScenarioError, match=r"line 2.*mu"):
        picopit.load_scenarios(str(tmp_path / "s.jsonl"))


# --- parameter and controller TOML ---------------------------------------------------------

NUMBER_LINE = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*)(\s*=\s*)([-+0-9.eE_]+|true|false|\"[^\"]*\")(.*)$")


def mutate_toml(text: str, rng: random.Random) -> tuple[str, str | None]:
    """Replace, delete or misspell one `key = value` line, or cut the file short."""
    lines = text.splitlines()
    idx = [i for i, l in enumerate(lines) if NUMBER_LINE.match(l)]
    i = rng.choice(idx)
    indent, key, eq, _, rest = NUMBER_LINE.match(lines[i]).groups()
    kind = rng.randrange(4)
    if kind == 0:
        lines[i] = f"{indent}{key}{eq}{rng.choice(TOML_HOSTILE)}"
    elif kind == 1:
        del lines[i]
    elif kind == 2:
        lines[i] = f"{indent}{key}_typo{eq}1.0"
        key = key + "_typo"
    else:
        body = "\n".join(lines)
        return body[: rng.randrange(len(body))], None
    return "\n".join(lines) + "\n", key


PARAM_FILES = [REPO / "crates" / "dynamics" / "params" / f"{s}.toml" for s in ("full_size", "half_scale")]


@pytest.mark.parametrize("seed", range(200))
def test_parameter_files(tmp_path, seed):
    rng = random.Random(seed)
    src = rng.choice(PARAM_FILES)
    text, key = mutate_toml(src.read_text(), rng)
    path = tmp_path / "p.toml"
    path.write_text(text)
    try:
        plant = picopit.Plant(str(path), mu=0.9)
    except picopit.ParamError as e:
        msg = str(e)
        if key is not None:
            assert key in msg, (seed, key, msg)
        return
    # Accepted (a deleted key with a default, a harmless value): the plant runs to finite states.
    plant.reset([-4.4, -1.95, 0, 15.5, 0, 0], [0, 0, 0, 15.0, 0, 0])
    plant.set_commands(0.05, 100.0)
    plant.advance(0.5)
    assert np.all(np.isfinite(plant.target_state())) and np.all(np.isfinite(plant.bullet_state())), seed


CONTROLLER = (REPO / "configs" / "controller_half_scale.toml").read_text()


@pytest.mark.parametrize("seed", range(150))
def test_controller_settings(seed):
    rng = random.Random(seed)
    text, key = mutate_toml(CONTROLLER, rng)
    try:
        ctrl = picopit.PitController("half_scale", 0.9, "4dof", settings=text)
    except picopit.PlannerError as e:
        msg = str(e)
        if key is not None:
            assert key in msg, (seed, key, msg)
        return
    ctrl.set_straight_road()
    out = ctrl.step(0.0, [2.2, 0, 0, 0, 0, 0, 5.0, 0], [1.0, 0.9, 0, 2.5, 0, 0])
    assert all(math.isfinite(v) for v in out["command"]), (seed, out)


# --- model files ---------------------------------------------------------------------------

MODEL = REPO / "models" / "full_size" / "picopinn.safetensors"


def mutate_model(data: bytes, rng: random.Random) -> bytes:
    """Flip bytes in the JSON header or the tensor data, cut the file, or edit one header entry."""
    n = int.from_bytes(data[:8], "little")
    kind = rng.randrange(4)
    b = bytearray(data)
    if kind == 0:  # a byte of the header
        i = rng.randrange(8, 8 + n)
        b[i] = rng.randrange(256)
    elif kind == 1:  # bytes of the tensor data
        for _ in range(rng.randrange(1, 8)):
            i = rng.randrange(8 + n, len(b))
            b[i] = rng.randrange(256)
    elif kind == 2:
        return bytes(b[: rng.randrange(len(b))])
    else:  # one header entry: a metadata value or a tensor's dtype, shape or offsets
        header = json.loads(bytes(b[8:8 + n]))
        name = rng.choice(list(header))
        if name == "__metadata__":
            k = rng.choice(list(header[name]))
            header[name][k] = rng.choice(["", "x", "-1", "1e308", "nan", "[]", "{}"])
        else:
            field = rng.choice(["dtype", "shape", "data_offsets"])
            header[name][field] = rng.choice(["F16", "I64", [0], [1, 2, 3], [-1, 5], [10**12, 10**12 + 8], "x"])
        h = json.dumps(header).encode()
        h += b" " * (-len(h) % 8)
        return len(h).to_bytes(8, "little") + h + bytes(b[8 + n:])
    return bytes(b)


@pytest.mark.parametrize("seed", range(200))
def test_model_files(tmp_path, seed):
    rng = random.Random(seed)
    path = tmp_path / "m.safetensors"
    path.write_bytes(mutate_model(MODEL.read_bytes(), rng))
    try:
        model = picopit.SurrogateModel(str(path), mu=0.9)
    except picopit.ModelError as e:
        assert str(e).strip(), seed
        return
    # Accepted (a flipped weight that still gives finite outputs on the file's own
    # statistics): a step from a plain driving state is finite.
    x = model.step([15.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0])
    assert np.all(np.isfinite(x)), seed


# --- MCAP recordings for `picopit replay` ---------------------------------------------------

MCAP_TOPICS = ["/state", "/command", "/status", "/heartbeat/controller", "/heartbeat/vehicle", "/scene",
               "/bullet/pose", "/target/pose"]


def mcap_edit(rng: random.Random):
    """An edit for tests/test_replay.py's `write_recording`: one field of one message set to a
    hostile value or deleted, or the whole message replaced."""
    topic, k = rng.choice(MCAP_TOPICS), rng.randrange(20)
    choice = rng.random()

    def edit(t, kk, msg):
        if (t, kk) != (topic, k):
            return msg
        if choice < 0.1:
            return rng.choice(HOSTILE[:6] + [[], "x", None])
        msg = json.loads(json.dumps(msg))
        paths = [p for p, _ in leaves(msg) if p]
        path = rng.choice(paths)
        if choice < 0.4 and not isinstance(path[-1], int):
            del_at(msg, path)
        else:
            set_at(msg, path, rng.choice(HOSTILE))
        return msg

    return edit


def mutate_bytes(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    if rng.random() < 0.3:
        return bytes(b[: rng.randrange(len(b))])
    for _ in range(rng.randrange(1, 16)):
        b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


@pytest.mark.parametrize("seed", range(150))
def test_mcap_recordings(tmp_path, seed):
    from test_replay import write_recording

    from picopit.replay import ReplayError, check_messages, read_recording

    rng = random.Random(seed)
    path = tmp_path / "run.mcap"
    if seed % 2:
        write_recording(path, n=20, edit=mcap_edit(rng), finish=rng.random() < 0.7)
    else:
        write_recording(path, n=20)
        path.write_bytes(mutate_bytes(path.read_bytes(), rng))
    try:
        check_messages(read_recording(path))
    except ReplayError as e:
        assert str(e).strip() and "\n" not in str(e).strip(), str(e)


@pytest.mark.parametrize("seed", range(0, 150, 15))
def test_mcap_replays_from_the_command_line(tmp_path, capsys, seed):
    """The whole command on a few of the cases above: it draws (exit 0) or says why in one
    line (exit 2), never a traceback."""
    from test_replay import write_recording

    from picopit import cli

    rng = random.Random(seed)
    path = tmp_path / "run.mcap"
    if seed % 2:
        write_recording(path, n=20, edit=mcap_edit(rng), finish=rng.random() < 0.7)
    else:
        write_recording(path, n=20)
        path.write_bytes(mutate_bytes(path.read_bytes(), rng))
    rc = cli.main(["replay", str(path), "--out", str(tmp_path / "fig.png")])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert rc in (0, 2), (rc, err)
    if rc == 2:
        assert len(err.strip().splitlines()) == 1, err
    else:
        assert (tmp_path / "fig.png").stat().st_size > 0
