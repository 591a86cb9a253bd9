"""Parameter sets across the binding: loading, round trip, and typed errors naming the field."""

from __future__ import annotations

import math

import pytest

import picopit


def test_builtin_sets_are_listed_and_load():
    names = picopit.builtin_param_sets()
    assert names == ["full_size", "half_scale"]
    for name in names:
        d = picopit.load_params_dict(name)
        assert set(d) == {"bullet", "target", "contact"}
        assert d["bullet"]["mass"] > 0 and d["target"]["mass"] > 0


def test_half_scale_matches_the_paper_platform():
    d = picopit.load_params_dict("half_scale")
    assert d["bullet"]["mass"] == pytest.approx(290.0)
    assert (d["bullet"]["length"], d["bullet"]["width"]) == pytest.approx((2.10, 1.12))
    assert d["target"]["mass"] == pytest.approx(100.0)
    assert (d["target"]["length"], d["target"]["width"]) == pytest.approx((1.90, 0.90))


def test_returned_text_round_trips_through_a_file(tmp_path):
    text = picopit.load_params("half_scale")
    path = tmp_path / "copy.toml"
    path.write_text(text)
    assert picopit.load_params(str(path)) == text


def test_param_error_is_a_value_error_exported_at_top_level():
    assert issubclass(picopit.ParamError, ValueError)
    assert picopit.ParamError is picopit._core.ParamError
    assert picopit.ParamError.__module__ == "picopit"


@pytest.mark.parametrize(
    "table, key, line, expect",
    [
        ("target", "mass", "mass = -1200.0", "target.mass"),
        ("bullet", "iz", "iz = nan", "bullet.iz"),
        ("bullet.tyre", "pdy1", "pdy1 = inf", "bullet.tyre.pdy1"),
        ("contact", "friction", "friction = -0.4", "contact.friction"),
        ("target", "brake_bias_front", "brake_bias_front = 1.5", "target.brake_bias_front"),
        ("target", "mass", "mass = 1e308", "target.mass = 1e308: outside the physical range"),
        ("bullet", "iz", "iz = 1e-9", "bullet.iz = 1e-9: outside the physical range [0.01, 1e6] kg m^2"),
        ("contact", "stiffness", "stiffness = 1e15", "contact.stiffness = 1e15: outside the physical range [1000, 1e8] N/m"),
        ("bullet.tyre", "pdy1", "pdy1 = 1e308", "bullet.tyre.pdy1 = 1e308: outside"),
        ("target", "mass", None, "mass"),  # missing field
        ("contact", "restitution", "restitution = 0.3\nwobble = 2.0", "wobble"),  # unknown field
    ],
)
def test_bad_field_raises_param_error_naming_it(param_file, table, key, line, expect):
    path = param_file(table, key, line)
    with pytest.raises(picopit.ParamError) as info:
        picopit.load_params(path)
    assert expect in str(info.value)


def test_negative_mass_message_is_specific(param_file):
    path = param_file("target", "mass", "mass = -3.0")
    with pytest.raises(picopit.ParamError, match=r"target\.mass = -3: must be positive"):
        picopit.load_params(path)


def test_unknown_set_and_missing_file_raise_param_error(tmp_path):
    with pytest.raises(picopit.ParamError):
        picopit.load_params("monster_truck")
    with pytest.raises(picopit.ParamError, match="cannot read"):
        picopit.load_params(str(tmp_path / "nope.toml"))


def test_malformed_toml_raises_param_error(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[bullet\nmass = 3\n")
    with pytest.raises(picopit.ParamError, match="broken.toml"):
        picopit.load_params(str(path))


def test_wrap_angle():
    assert picopit.wrap_angle(3.5 * math.pi) == pytest.approx(-0.5 * math.pi)
    assert picopit.wrap_angle(math.pi) == pytest.approx(math.pi)
