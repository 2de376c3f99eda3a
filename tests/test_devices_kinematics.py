"""The force mapping every arm shares: one scale factor keeps the force's direction."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from sasprobe.devices.kinematics import scale_to_limit


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6), min_size=3, max_size=3), st.floats(1e-3, 10.0))
def test_scale_to_limit_never_exceeds_and_keeps_direction(torques, limit):
    scaled, factor = scale_to_limit(np.array(torques), limit)
    assert np.all(np.abs(scaled) <= limit * (1 + 1e-12))
    np.testing.assert_allclose(scaled, factor * np.array(torques), rtol=1e-12, atol=1e-300)


def test_a_non_finite_torque_gives_zero():
    scaled, factor = scale_to_limit(np.array([np.nan, 1.0, 0.0]), 1.0)
    assert factor == 0.0 and np.all(scaled == 0.0)
