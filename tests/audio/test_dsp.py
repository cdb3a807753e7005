"""studyapp.audio.dsp gives scipy's results (the participant's install has no scipy; the tests' does).

Each routine is compared with the scipy function it replaces, on random input and on the edge cases of its
algorithm (plateaus and equal heights for peaks, signals shorter than the kernel, rate pairs whose filter is
longer than the clip).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage, signal

from studyapp.audio import dsp


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("up,down,n", [(3, 1, 1000), (1, 3, 1001), (160, 147, 4410), (147, 160, 4800),
                                       (2, 3, 7), (48000, 16000, 500), (16000, 48000, 501), (5, 1, 1),
                                       (1, 7, 3), (441, 480, 9000)])
def test_resample_poly_is_scipys(up: int, down: int, n: int, dtype) -> None:
    rng = np.random.default_rng(n + up)
    for x in (rng.standard_normal((n, 2)).astype(dtype), rng.standard_normal(n).astype(dtype)):
        want = signal.resample_poly(x, up, down, axis=0)
        got = dsp.resample_poly(x, up, down, axis=0)
        assert got.shape == want.shape and got.dtype == want.dtype
        np.testing.assert_allclose(got, want, rtol=0, atol=2e-6 if dtype == np.float32 else 1e-13)


def test_resample_poly_on_another_axis_and_ints() -> None:
    x = np.arange(60, dtype=np.int16).reshape(2, 30)
    np.testing.assert_allclose(dsp.resample_poly(x, 2, 1, axis=1), signal.resample_poly(x, 2, 1, axis=1),
                               atol=1e-12)


@pytest.mark.parametrize("mode", ["reflect", "nearest"])
@pytest.mark.parametrize("n", [1, 2, 5, 50, 301])
@pytest.mark.parametrize("sigma", [0.2, 0.5, 1.5, 5.0, 20.0])
def test_gaussian_filter1d_is_scipys(mode: str, n: int, sigma: float) -> None:
    x = np.random.default_rng(n).standard_normal(n)
    np.testing.assert_allclose(dsp.gaussian_filter1d(x, sigma, mode=mode),
                               ndimage.gaussian_filter1d(x, sigma, mode=mode), rtol=0, atol=1e-13)


def test_find_peaks_is_scipys() -> None:
    rng = np.random.default_rng(7)
    for trial in range(400):
        n = int(rng.integers(1, 200))
        x = rng.standard_normal(n)
        if trial % 2:
            x = np.round(x, 1)  # plateaus and equal heights
        height = float(rng.uniform(-1, 1)) if trial % 3 else None
        distance = int(rng.integers(1, 12)) if trial % 5 else None
        want, _ = signal.find_peaks(x, height=height, distance=distance)
        np.testing.assert_array_equal(dsp.find_peaks(x, height=height, distance=distance), want)


def test_find_peaks_plateau_middle_and_edges() -> None:
    x = np.array([3.0, 1, 2, 2, 2, 2, 1, 0, 1, 1, 5])
    assert dsp.find_peaks(x).tolist() == signal.find_peaks(x)[0].tolist() == [3]
