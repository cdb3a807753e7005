"""A CSV's row places (``_where``) are stored as line numbers and read as the texts ``line N``: each pandas
operation the analysis applies to a frame gives what the same column of Python strings gives."""
from __future__ import annotations

import pickle

import numpy as np
import pandas as pd
import pytest

from results_analysis.loader import load_results
from results_analysis.where_labels import PlaceArray


@pytest.fixture
def pair() -> tuple[pd.DataFrame, pd.DataFrame]:
    """The same frame with places as numbers (ours) and as strings (reference)."""
    n = 50
    base = pd.DataFrame({"k": np.arange(n) % 7, "v": np.arange(n) * 0.5})
    ours = base.assign(_where=pd.Series(PlaceArray.lines(n), index=base.index))
    ref = base.assign(_where=pd.Series([f"line {i + 2}" for i in range(n)], index=base.index, dtype=object))
    return ours, ref


def _same(a, b) -> None:
    if isinstance(a, pd.DataFrame):
        assert a.columns.tolist() == b.columns.tolist() and a.index.tolist() == b.index.tolist()
        for c in a.columns:
            _same(a[c].tolist(), b[c].tolist())
    else:
        a, b = list(a), list(b)
        assert [None if pd.isna(x) else x for x in a] == [None if pd.isna(x) else x for x in b]
        assert [type(x) for x in a] == [type(x) for x in b]


@pytest.mark.parametrize("op", [
    lambda d: d[d["k"] > 3],
    lambda d: d.iloc[[5, 1, 1, 40]],
    lambda d: d.loc[d.index[::3]],
    lambda d: d.sort_values("v", ascending=False),
    lambda d: d.reset_index(drop=True).copy(),
    lambda d: d.reindex([0, 3, 99]),                    # a row without a place reads as NaN
    lambda d: pd.concat([d.iloc[:4], d.iloc[10:12]]),
    lambda d: d.groupby("k", sort=True).first(),
    lambda d: d.drop_duplicates("k"),
    lambda d: d.merge(pd.DataFrame({"k": [1, 2], "w": [9, 8]}), on="k"),
    lambda d: d["_where"] == "line 7",
    lambda d: d["_where"].iloc[[2, 3]].tolist(),
    lambda d: d["_where"].to_numpy(),
    lambda d: d["_where"].astype(str),
    lambda d: pickle.loads(pickle.dumps(d)),
    lambda d: pd.concat([d, pd.DataFrame({"k": [1]})], ignore_index=True),  # a frame without places
    lambda d: d["_where"].where(d["k"] > 2),
    lambda d: d["_where"].mask(d["k"] == 2, "line 99"),
    lambda d: d["_where"].unique(),
    lambda d: d["_where"].value_counts().sort_index(),
    lambda d: [d["_where"].nunique()],
])
def test_places_behave_as_their_texts(pair, op) -> None:
    ours, ref = pair
    _same(op(ours), op(ref))


def test_a_loaded_csv_keeps_its_places_as_numbers_and_names_lines_in_errors(tmp_path) -> None:
    p = tmp_path / "r.csv"
    rows = "".join(f"P1,{t},c{t},realism,{c},{r}\n" for t in range(40) for c, r in (("A", 1), ("B", 2)))
    p.write_text("participant,trial_index,stimulus,criterion,condition,rank\n" + rows)
    df = load_results(p)
    assert isinstance(df["_where"].array, PlaceArray)  # numbers, not 80 Python strings
    assert df["_where"].iloc[0] == "line 2" and df["_where"].iloc[-1] == "line 81"
    p.write_text(p.read_text().replace("P1,39,c39,realism,B,2", "P1,39,c39,realism,B,x"))
    with pytest.raises(Exception, match="line 81, column 'rank'"):
        load_results(p)


def test_text_that_is_no_place_is_refused_with_the_way_out(pair) -> None:
    ours, _ = pair
    with pytest.raises(TypeError, match=r"'n/a' is not a row place .*astype\(object\)"):
        ours["_where"].mask(ours["k"] == 2, "n/a")
    assert ours["_where"].astype(object).mask(ours["k"] == 2, "n/a").iloc[2] == "n/a"
