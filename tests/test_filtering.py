"""The Butterworth design and the forward-backward filter written out in filtering.py against
scipy.signal's butter and filtfilt, the oracle they reproduce: equal to the bit on generated
orders, cutoffs and signal shapes, through the numpy recursion and through lfilter (long
signals); and the fccgrb solve path does not import scipy.signal."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.signal as oracle

from fccgrb_cli.signals import butterworth as filtering

ROOT = Path(__file__).resolve().parents[1]


def _cases(seed: int, count: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        order = int(rng.integers(1, 7))
        wn = float(rng.uniform(0.004, 0.96))
        frames = int(rng.integers(3 * (order + 1) + 1, 400))
        shape = (frames, *rng.integers(1, 5, size=int(rng.integers(0, 3))))
        yield order, wn, rng.normal(size=shape).cumsum(axis=0) * rng.uniform(1e-3, 1e3)


@pytest.mark.parametrize("long", [False, True])
def test_butter_and_filtfilt_are_scipy_to_the_bit(long, monkeypatch):
    """Through the numpy loop (what a solve in a fresh process runs) and through lfilter (a
    long signal, or scipy.signal already imported: this test's process has it)."""
    monkeypatch.setattr(filtering, "in_lfilter", lambda samples: long)
    for order, wn, x in _cases(7 + long, 60):
        b, a = filtering.butter(order, wn)
        b0, a0 = oracle.butter(order, wn)
        assert np.array_equal(b, b0) and np.array_equal(a, a0), (order, wn)
        assert np.array_equal(filtering.filtfilt(b, a, x), oracle.filtfilt(b0, a0, x, axis=0)), \
            (order, wn, x.shape)


def test_lowpass_keeps_the_band_and_removes_the_rest():
    """Sines through a 6 Hz filter at 200 Hz come out scaled by the squared digital
    Butterworth response, 1 / (1 + (tan(π f / rate) / tan(π fc / rate))^(2n)) per pass
    (the bilinear transform's prewarped frequency), away from the ends."""
    rate, fc, t = 200.0, 6.0, np.arange(4000) / 200.0
    for f in (1.0, 2.0, 6.0, 15.0, 40.0):
        out = filtering.lowpass(np.sin(2 * np.pi * f * t)[:, None], rate, fc)
        gain = np.sqrt(2 * np.mean(out[1000:3000] ** 2))  # 10 s: whole periods
        ratio = np.tan(np.pi * f / rate) / np.tan(np.pi * fc / rate)
        assert gain == pytest.approx(1 / (1 + ratio**4), rel=1e-3), f


def test_the_recursion_runs_in_lfilter_when_long_or_already_imported(monkeypatch):
    assert filtering.in_lfilter(50)  # this process imported scipy.signal
    monkeypatch.delitem(sys.modules, "scipy.signal")
    assert not filtering.in_lfilter(filtering.LONG)
    assert filtering.in_lfilter(filtering.LONG + 1)
    code = ("from fccgrb_cli.signals import butterworth as f; print(f.in_lfilter(50)); "
            "f.preload(); print(f.in_lfilter(50))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "True"]


def test_a_solve_does_not_import_scipy_signal():
    """The sample's solve with dynamics (and the moments' noise test, which filters) in a fresh
    process leaves scipy.signal unloaded."""
    code = ("import sys; from fccgrb_cli.api import load_model, read_trial, solve; "
            "solve(load_model('configs/models/five_bar.yaml'), "
            "read_trial('sample_data/five_bar.c3d'), method='nrm-wls', smooth='none'); "
            "print('scipy.signal' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip().splitlines()[-1] == "False"
