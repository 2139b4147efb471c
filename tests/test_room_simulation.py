"""scripts/room_simulation.py: the GCC-PHAT delay picks the direct sound, not a stronger reflection."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("room_simulation", ROOT / "scripts" / "room_simulation.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["room_simulation"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("seed", range(6))
def test_gcc_phat_search_back_finds_the_direct_sound_before_a_stronger_reflection(seed):
    sim = _script()
    rng = np.random.default_rng(seed)
    fs = sim.FS
    reference = rng.standard_normal(1600)
    direct, echo = 3000 + int(rng.integers(500)), int(rng.integers(20, 200))  # samples; echo <= 12.5 ms later
    recording = 0.01 * rng.standard_normal(8000)
    recording[direct : direct + 1600] += 0.85 * reference
    recording[direct + echo : direct + echo + 1600] += 1.0 * reference  # two reflections adding up
    # PHAT keeps only the phase: the direct sound's peak is about 0.6 of the reflection's (above the 0.5 bar)
    highest, peak = sim.gcc_phat_delay(recording, reference, fs, max_delay=0.4)
    first, peak_back = sim.gcc_phat_delay(recording, reference, fs, max_delay=0.4, search_back=0.02)
    assert highest * fs == pytest.approx(direct + echo, abs=0.1)
    assert first * fs == pytest.approx(direct, abs=0.1)
    assert peak == peak_back > 8  # the detection statistic is that of the highest peak either way
