"""A replaced structure and engine are freed off the loop, an array at a time."""

from __future__ import annotations

import weakref

import numpy as np
from sasprobe.daemon.deferred_release import DeferredRelease, arrays_within
from sasprobe.daemon.haptics import build_engine
from sasprobe.devices.simulated.arm import make_simulated


def test_the_arrays_of_a_structure_and_its_engine_are_all_found(crambin):
    engine = build_engine(crambin, make_simulated("scan").info.limits, {"cube_half_A": "fit"})
    found = {id(a) for a in arrays_within((crambin, engine))}
    for name in ("positions", "vdw_radii", "elements", "chain_ids"):
        assert id(getattr(crambin, name)) in found, name
    grid_arrays = [v for v in vars(engine._grid).values() if isinstance(v, np.ndarray)]
    assert grid_arrays and all(id(a) in found for a in grid_arrays)


def test_release_frees_what_only_the_retired_held_and_keeps_what_others_hold():
    class Holder:
        def __init__(self):
            self.big = np.zeros(1 << 20)
            self.nested = {"list": [np.ones(10), (np.arange(5),)]}

    holder = Holder()
    kept = holder.nested["list"][0]  # someone else still uses this one
    refs = [weakref.ref(holder.big), weakref.ref(holder.nested["list"][1][0]), weakref.ref(kept)]
    retired = DeferredRelease()
    retired.add(holder)
    del holder
    assert all(r() is not None for r in refs)  # retired: alive until released
    retired.release()
    assert refs[0]() is None and refs[1]() is None
    assert refs[2]() is kept and kept.sum() == 10
