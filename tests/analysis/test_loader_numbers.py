"""The loader parses each distinct text of a numeric column once: the numbers (and the unreadable cells) are
those pandas.to_numeric gives cell by cell."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from results_analysis.loader import _to_number, load_results

ODD = ["1", "1.0", " 2", "2 ", "x", None, np.nan, "inf", "-inf", "1e3", "-0", "0x10", "9007199254740993", "1_000",
       "3.25", "", "NaN", "+4", ".5", "5."]


@pytest.mark.parametrize("seed", range(5))
def test_to_number_equals_to_numeric_cell_by_cell(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cells = [ODD[i] for i in rng.integers(0, len(ODD), 200)]
    for col in (pd.Series(cells, dtype=object), pd.Series([c for c in cells if c is not None and c == c], dtype=str)):
        ref = pd.Series([pd.to_numeric(pd.Series([c], dtype=object), errors="coerce").astype(float).iloc[0]
                         for c in col], index=col.index)
        pd.testing.assert_series_equal(_to_number(col), ref, check_exact=True)


def test_loaded_csv_keeps_its_dtypes_and_names_the_bad_line(tmp_path) -> None:
    p = tmp_path / "r.csv"
    p.write_text("participant,trial_index,stimulus,criterion,condition,rank,speaker\n"
                 "P1,0,c1,realism,A,1,s1\nP1,0,c1,realism,B,2,\n")
    df = load_results(p)
    assert df["rank"].tolist() == [1.0, 2.0] and df["trial_index"].dtype == float
    assert df["participant"].dtype == object and df["speaker"].dtype == pd.StringDtype(na_value=np.nan)
    assert df["speaker"].isna().tolist() == [False, True]
    p.write_text(p.read_text() + "P1,0,c1,realism,C,three,s1\n")
    with pytest.raises(Exception, match="line 4, column 'rank'"):
        load_results(p)
