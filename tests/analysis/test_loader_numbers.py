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


def test_a_row_with_too_many_fields_is_named_by_its_line_in_one_line(tmp_path) -> None:
    from results_analysis.errors import AnalysisInputError

    p = tmp_path / "r.csv"
    p.write_text("participant,trial_index,stimulus,criterion,condition,rank\n"
                 "P1,0,c1,realism,A,1\nP1,0,c1,realism,B,2,extra\n")
    with pytest.raises(AnalysisInputError) as err:
        load_results(p)
    assert str(err.value) == f"{p}: line 3: 7 fields where the header has 6 (a damaged or hand-edited row?)"


def _text_read(path) -> pd.DataFrame:
    """The loader's CSV path with every number cell read as text and parsed by normalize_results (what
    load_results did before it let pandas' C parser read the number columns)."""
    from results_analysis.loader import _read_text_csv, normalize_results

    df = _read_text_csv(path)
    df["_where"] = pd.Series([f"line {i + 2}" for i in range(len(df))], index=df.index, dtype=object)
    return normalize_results(df, source=path)


def _assert_same_frame(a: pd.DataFrame, b: pd.DataFrame) -> None:
    assert list(a["_where"]) == list(b["_where"])  # the same texts, however they are stored
    a, b = a.drop(columns="_where"), b.drop(columns="_where")
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert list(a.dtypes) == list(b.dtypes) and a.attrs == b.attrs
    for col in a.columns:
        if a[col].dtype.kind == "f":  # equal as numbers is not enough: -0.0 == 0.0
            assert (np.signbit(a[col].to_numpy()) == np.signbit(b[col].to_numpy())).all(), col


# cells pandas' C parser reads as numbers (and empty cells)
PLAIN = ["1", "1.0", " 2", "2 ", "inf", "-inf", "Infinity", "1e3", "1E-3", "9007199254740993", "3.25", "", "+4",
         ".5", "5.", "0", "0.0", "24.47892459055034", "0.1000000000000000055511151231257827", "1e400",
         "12345678901234567890123", "2.2250738585072011e-308"]


@pytest.mark.parametrize("seed", range(4))
def test_number_columns_parsed_in_c_equal_the_text_read(tmp_path, seed: int) -> None:
    from results_analysis.loader import _read_numbers_csv

    rng = np.random.default_rng(seed)
    n = 120
    # the named cells, and as many full-precision floats (the last digit decides the rounding)
    cells = lambda: [PLAIN[i] if i < len(PLAIN) else repr(float(rng.lognormal(0, 8)))  # noqa: E731
                     for i in rng.integers(0, 2 * len(PLAIN), n)]
    df = pd.DataFrame({"participant": [f"P{i // 6}" for i in range(n)], "trial_index": rng.integers(0, 9, n),
                       "stimulus": "c1", "criterion": "realism", "condition": [f"C{i % 3}" for i in range(n)],
                       "rank": rng.integers(1, 4, n).astype(str), "slot": cells(), "plays": cells(),
                       "response_time_s": cells(), "rating": cells(), "preference": cells(), "speaker": "s1"})
    p = tmp_path / "r.csv"
    df.to_csv(p, index=False)
    fast = _read_numbers_csv(p)
    assert fast is not None and fast["response_time_s"].dtype == np.float64  # the C parser read them
    _assert_same_frame(load_results(p), _text_read(p))


@pytest.mark.parametrize("cell", ["-0", "-0.0", "nan", "NaN", "x", "0x10", "1_000", "True"])
def test_cells_c_reads_otherwise_are_read_as_text(tmp_path, cell: str) -> None:
    """``-0`` is the integer 0 to pandas.to_numeric but -0.0 to the C parser; ``nan`` is a number to neither
    rule in this column; the rest C cannot parse: each file is read as text, with the same frame or error."""
    from results_analysis.loader import _read_numbers_csv

    p = tmp_path / "r.csv"
    p.write_text("participant,trial_index,stimulus,criterion,condition,rank,response_time_s\n"
                 "P1,0,c1,realism,A,1,2.5\nP1,0,c1,realism,B,2,3\nP1,0,c1,realism,C,3," + cell + "\n")
    assert _read_numbers_csv(p) is None
    try:
        expected = _text_read(p)
    except Exception as exc:  # noqa: BLE001 - the same error, word for word
        with pytest.raises(type(exc)) as got:
            load_results(p)
        assert str(got.value) == str(exc) and "line 4, column 'response_time_s'" in str(exc)
    else:
        _assert_same_frame(load_results(p), expected)


FLAGS = ["True", "False", "true", "0", "1", "yes", "n", "1.0", " T ", None, np.nan, True, False, 1, 0.0]


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("choices", [FLAGS[:2], FLAGS])  # as pandas writes flags (the fast path), and any
def test_flags_read_as_each_cell_reads_alone(seed: int, choices: list) -> None:
    from results_analysis.loader import _flag_value, _parse_flags

    rng = np.random.default_rng(seed)
    cells = [choices[i] for i in rng.integers(0, len(choices), 300)]
    col = pd.Series(cells, dtype=object)
    where = pd.Series([f"line {i + 2}" for i in range(len(col))])
    got = _parse_flags(col, "is_practice", where, "r.csv", default=False)
    expected = [False if c is None or (isinstance(c, float) and np.isnan(c)) else _flag_value(c, False) for c in cells]
    assert got.dtype == bool and got.tolist() == expected
    bad = col.where(col.index != 7, "maybe")
    with pytest.raises(Exception, match="line 9, column 'is_practice': 'maybe' is not a true/false flag"):
        _parse_flags(bad, "is_practice", where, "r.csv", default=False)
