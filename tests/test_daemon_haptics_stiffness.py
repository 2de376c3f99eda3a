"""The default stiffness follows the loop's rate: half the largest stable one, the smaller of
the arm's rating and the sampled-wall passivity bound 2(b − B)/T (Colgate & Schenkel), and
it is stable where it says it is: on the simulated arm (its physics integrated in substeps,
the force held over each period, a hand without a person's limit), the press cycle at the
default of each rate gives back less than 1 mJ, while four times the 1 kHz default, twice
the bound, gains energy. docs/haptics.md lists the default per arm; the list is checked
against the code here."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import pytest
from sasprobe.daemon.haptics import HapticEngine, HapticSettings
from sasprobe.daemon.haptics.settings import default_stiffness, validate_settings
from sasprobe.devices.base import PHANTOM_OMNI_LIMITS
from sasprobe.devices.falcon.models import FALCON_LIMITS
from sasprobe.devices.forcedimension.models import MODELS as DHD_MODELS
from sasprobe.devices.haply.models import GENERATIONS
from sasprobe.devices.inverse3.models import MODELS as INVERSE_MODELS
from sasprobe.devices.simulated.arm import ArmModel, make_simulated
from sasprobe.devices.woodenhaptics.models import WOODEN_MODELS
from sasprobe.molecule import load_default

ROOT = Path(__file__).resolve().parents[1]
DAMPING = 0.2  # the daemon's default virtual damping
ENERGY_UNSTABLE_MJ = 1.0
OMEGA = DHD_MODELS[33].limits  # rated 5 N/mm: above the bound at 1 and 2 kHz


def bound_n_per_mm(limits, rate_hz, damping=DAMPING):
    """Colgate & Schenkel's K < 2(b − B)/T, from the arm's held damping."""
    return 2.0 * (limits.held_damping_n_s_per_m - damping) / (1.0 / rate_hz) / 1000.0


def test_the_default_is_half_the_smaller_of_the_rating_and_the_bound_and_grows_with_rate():
    defaults = [default_stiffness(OMEGA, r, DAMPING) for r in (1000, 2000, 4000)]
    assert defaults == sorted(defaults) and defaults[0] < defaults[-1]
    for rate, k in zip((1000, 2000, 4000), defaults):
        assert k == pytest.approx(
            0.5 * min(OMEGA.max_stiffness_n_per_mm, bound_n_per_mm(OMEGA, rate))
        )
    omni = [default_stiffness(PHANTOM_OMNI_LIMITS, r, DAMPING) for r in (1000, 4000)]
    assert omni == [0.5 * PHANTOM_OMNI_LIMITS.max_stiffness_n_per_mm] * 2  # the rating caps it
    # the daemon fills it in for its rate; a stiffness given stays as given
    settings = validate_settings({}, OMEGA, 4000.0)
    assert settings["stiffness_n_per_mm"] == defaults[-1]
    assert (
        validate_settings({"stiffness_n_per_mm": 0.4}, OMEGA, 4000.0)["stiffness_n_per_mm"] == 0.4
    )
    # virtual damping at or above the arm's own leaves no passive stiffness: a soft default
    assert 0.0 < default_stiffness(OMEGA, 1000, 2.0) <= 0.1


def press_energy_mj(rate_hz: float, stiffness: float) -> float:
    """The simulated arm pressed into crambin and released, closed loop at `rate_hz`."""
    structure = load_default()
    limits = dataclasses.replace(PHANTOM_OMNI_LIMITS, max_stiffness_n_per_mm=20.0)
    device = make_simulated(
        "press",
        structure=structure,
        rate_hz=rate_hz,
        limits=limits,
        arm=ArmModel(max_hand_force_n=math.inf),
        cube_half_A="fit",
    )
    engine = HapticEngine(
        structure, limits, HapticSettings(stiffness_n_per_mm=stiffness, cube_half_A="fit")
    )
    device.open()
    for _ in range(int(round(device.hand_path.duration_s * rate_hz))):
        device.write_force(engine.step(device.read()).force_n)
    return device.work_mj


@pytest.mark.parametrize("rate_hz", [1000, 2000, 4000])
def test_the_default_of_each_rate_is_stable_on_the_simulated_arm(rate_hz):
    held = ArmModel().arm_damping_n_s_per_m + ArmModel().hand_damping_n_s_per_m
    assert OMEGA.held_damping_n_s_per_m == held  # the arm every rating is taken to be held like
    assert press_energy_mj(rate_hz, default_stiffness(OMEGA, rate_hz, DAMPING)) < ENERGY_UNSTABLE_MJ


def test_twice_the_bound_is_unstable_on_the_simulated_arm():
    """What the margin is for: the map's frontier lies between the bound and twice it."""
    stiffness = 2.0 * bound_n_per_mm(OMEGA, 1000)
    assert press_energy_mj(1000, stiffness) > ENERGY_UNSTABLE_MJ


ARMS = {  # docs/haptics.md's rows → the limits the drivers declare (None: the simulated arm's)
    "simulated arm": None,
    "PHANTOM Omni (OpenHaptics)": PHANTOM_OMNI_LIMITS,
    "Novint Falcon": FALCON_LIMITS,
    "Force Dimension omega.x, delta.3": DHD_MODELS[33].limits,
    "Force Dimension sigma.7": DHD_MODELS[104].limits,
    "Force Dimension lambda.7": DHD_MODELS[108].limits,
    "Novint Falcon through DHD": DHD_MODELS[60].limits,
    "Haply Inverse3, Minverse": INVERSE_MODELS["inverse3"].limits,
    "Haply 2DIY": GENERATIONS["gen3"].limits,
    "WoodenHaptics Polhem": WOODEN_MODELS[1].limits,
    "WoodenHaptics Woody": WOODEN_MODELS[3].limits,
    "vintage PHANTOM (WoodenHaptics)": WOODEN_MODELS[2].limits,
}


def test_docs_list_each_arms_default_at_each_rate_it_runs():
    text = (ROOT / "docs" / "haptics.md").read_text()
    section = text[text.index("### Default stiffness") :]
    rows = re.findall(
        r"^\| ([^|]+?) \| ([\d.]+) \| ([\d.]+) \| ([\d.–-]+) \| ([\d.–-]+) \|$", section, re.M
    )
    assert {name for name, *_ in rows} == set(ARMS)
    assert DHD_MODELS[63].limits.max_stiffness_n_per_mm == OMEGA.max_stiffness_n_per_mm  # delta.3
    for name, rated, *by_rate in rows:
        limits = ARMS[name] or make_simulated("scan").info.limits
        assert float(rated) == limits.max_stiffness_n_per_mm, name
        for rate, text_value in zip((1000, 2000, 4000), by_rate):
            if rate > limits.max_rate_hz:
                assert text_value in "–-", f"{name} does not run at {rate} Hz"
            else:
                expected = default_stiffness(limits, rate, DAMPING)
                assert float(text_value) == pytest.approx(expected, abs=0.005), (name, rate)
