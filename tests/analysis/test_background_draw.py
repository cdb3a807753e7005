"""Resample matrices drawn in the background (while the analysis computes what needs none) are the matrices
drawn in the foreground, are shared with later callers, and no drawing thread outlives the block."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from results_analysis.bootstrap import resample_weights, shared_draw, shared_resamples
from results_analysis.descriptives import bootstrap_weights


def _drawing_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == "results_analysis-resamples"]


def test_background_draws_equal_foreground_draws_and_are_shared() -> None:
    ref = resample_weights(257, 300, 4).copy()
    assert np.array_equal(bootstrap_weights(257, 300, 4), ref)  # the mean-rank resamples are the index draws
    with shared_resamples():
        assert resample_weights(257, 300, 4, background=True) is None
        m, i = bootstrap_weights(257, 200, 4), resample_weights(257, 300, 4)
        assert np.array_equal(m, ref[:200]) and np.array_equal(i, ref)
        assert m.base is i.base  # the same matrix, drawn once
        assert not m.flags.writeable
    assert not _drawing_threads()


def test_a_failed_background_draw_fails_the_caller_and_leaves_no_thread() -> None:
    def draw(n: int) -> np.ndarray:
        raise MemoryError("no room")
    with shared_resamples():
        shared_draw("k", 10, draw, background=True)
        with pytest.raises(MemoryError, match="no room"):
            shared_draw("k", 10, draw)
    with shared_resamples():  # left unused: the block still waits for it
        shared_draw("k", 10, lambda n: np.zeros((n, 3)), background=True)
    assert not _drawing_threads()
