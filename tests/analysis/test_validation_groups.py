"""The validation checks group rows by codes factorized once (issue 20): the duplicate flags and per-trial
sizes equal pandas' ``duplicated(keep=False)`` and ``groupby(...).transform("size")``, which they replace."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from results_analysis.simulate import simulate_results
from results_analysis.validate import _codes, _sizes


@pytest.mark.parametrize("seed", range(6))
def test_sizes_equal_pandas_grouping(seed: int) -> None:
    rng = np.random.default_rng(seed)
    df = simulate_results(int(rng.integers(1, 9)), 3, seed=seed)
    df = pd.concat([df, df.sample(int(rng.integers(0, 6)), random_state=seed)])  # duplicated answers
    df = df.sample(frac=1, random_state=seed)
    df = df[rng.random(len(df)) > 0.1]  # incomplete trials
    cols = ["participant", "trial_index", "criterion", "condition"]
    codes = _codes(df, cols)
    assert np.array_equal(_sizes(codes) > 1, df.duplicated(cols, keep=False).to_numpy())
    assert np.array_equal(_sizes(codes[:-1]),
                          df.groupby(cols[:-1], sort=False)["condition"].transform("size").to_numpy())


def test_a_missing_key_value_leaves_the_grouping_to_pandas() -> None:
    df = pd.DataFrame({"participant": ["P1", None], "trial_index": [0, 0]})
    assert _codes(df, ["participant", "trial_index"]) is None
