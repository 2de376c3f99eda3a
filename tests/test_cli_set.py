"""`sasprobe set KEY=VALUE ...` turned into the control `set` fields protocol/README.md
defines: every key the pages show, and one line for a bad value."""

from __future__ import annotations

import pytest

from sasprobe.cli.commands.set import set_fields
from sasprobe.common.errors import UserError


@pytest.mark.parametrize(
    "pairs, fields",
    [
        (["stiffness=0.2", "probe-radius=1.2"], {"stiffness_n_per_mm": 0.2, "probe_radius_A": 1.2}),
        (["cube-half=fit"], {"cube_half_A": "fit"}),
        (["cube-half=default"], {"cube_half_A": None}),
        (["clip=0,0,1,-5", "clip=1,0,0,-20"], {"clip_planes": [[0, 0, 1, -5], [1, 0, 0, -20]]}),
        (["clip=none"], {"clip_planes": []}),
        (["probe-light=off"], {"lights": {"probe": {"enabled": False}}}),
        (["color=chain"], {"color_scheme": "chain"}),
        (["color=Hydrophobicity"], {"color_scheme": "hydrophobicity"}),
        (["color=default"], {"color_scheme": None}),
    ],
)
def test_keys_become_the_set_fields(pairs, fields):
    assert set_fields(pairs) == fields


@pytest.mark.parametrize(
    "pair, message",
    [
        ("color=rainbow", "color=rainbow: expected default or one of element, chain"),
        ("colour=chain", "expected KEY=VALUE with KEY one of"),
        ("stiffness=stiff", "stiffness=stiff: expected a number"),
    ],
)
def test_a_bad_pair_is_one_line(pair, message):
    with pytest.raises(UserError, match=message) as caught:
        set_fields([pair])
    assert "\n" not in str(caught.value)
