"""Array arguments at the binding boundary: shape and finiteness are checked, data is copied."""

from __future__ import annotations

import math

import numpy as np
import pytest

import picopit


def test_footprint_corners_match_hand_computation():
    c = picopit.footprint([1.0, 2.0, 0.0], 4.0, 2.0, 3.0)
    assert c.shape == (4, 2) and c.dtype == np.float64
    np.testing.assert_allclose(c, [[4.0, 3.0], [0.0, 3.0], [0.0, 1.0], [4.0, 1.0]], atol=1e-12)
    r = picopit.footprint([0.0, 0.0, math.pi / 2], 4.0, 2.0, 3.0)
    np.testing.assert_allclose(r[0], [-1.0, 3.0], atol=1e-12)  # front-left corner


@pytest.mark.parametrize(
    "pose, pattern",
    [
        ([0.0, 0.0], r"pose: expected shape \(3,\)"),
        ([[0.0, 0.0, 0.0]], r"pose: expected shape \(3,\)"),
        ([0.0, float("nan"), 0.0], r"pose\[1\] = NaN: must be finite"),
        ([0.0, 0.0, float("inf")], r"pose\[2\] = inf: must be finite"),
        ("abc", r"pose: expected an array of 3 floats"),
    ],
)
def test_bad_arrays_raise_value_error_naming_the_argument(pose, pattern):
    with pytest.raises(ValueError, match=pattern):
        picopit.footprint(pose, 4.0, 2.0, 3.0)


def test_bad_scalars_raise_value_error_naming_the_argument():
    with pytest.raises(ValueError, match="length"):
        picopit.footprint([0, 0, 0], -4.0, 2.0, 3.0)
    with pytest.raises(ValueError, match="cg_to_front"):
        picopit.footprint([0, 0, 0], 4.0, 2.0, float("nan"))


def test_strided_fortran_and_integer_inputs_are_copied_correctly():
    base = np.arange(12.0).reshape(3, 4)
    strided = base[:, 1]  # non-unit stride: [1, 5, 9]
    fortran = np.asfortranarray(base)[:, 1]
    expect = picopit.footprint([1.0, 5.0, 9.0], 4.0, 2.0, 3.0)
    np.testing.assert_array_equal(picopit.footprint(strided, 4.0, 2.0, 3.0), expect)
    np.testing.assert_array_equal(picopit.footprint(fortran, 4.0, 2.0, 3.0), expect)
    np.testing.assert_array_equal(
        picopit.footprint(np.array([1, 5, 9]), 4.0, 2.0, 3.0), expect
    )


def test_outputs_are_fresh_copies():
    a = picopit.footprint([0.0, 0.0, 0.0], 4.0, 2.0, 3.0)
    a[:] = 0.0
    b = picopit.footprint([0.0, 0.0, 0.0], 4.0, 2.0, 3.0)
    assert np.abs(b).max() > 0
