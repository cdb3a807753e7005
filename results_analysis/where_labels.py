"""The ``_where`` column of a frame read from a CSV (``line 12``: where a row came from, for messages), held as
line numbers and written out only when read.

A 10,000-participant export has about a million rows; as Python strings their places cost a fifth of a second
to write (and 60 MB) in every analysis, while only an error message ever reads one or two. :class:`PlaceArray`
is a pandas extension array of those numbers: a cell reads as its text (``"line 12"``), every whole-column
use (``to_numpy``, ``astype(object)``, ``tolist``, comparison with text, ``unique``) gives the texts, and
selecting rows (masks, ``take``, concatenation) moves the numbers only. A missing place (a row added by
reindexing or concatenation) reads as NaN, as in a column of strings. Only a place or NaN can be written
into it (text that is not a place: ``.astype(object)`` first).

>>> import pandas as pd
>>> s = pd.Series(PlaceArray.lines(3))
>>> s.iloc[2], s[s.index > 0].tolist(), bool((s == "line 3").iloc[1])
('line 4', ['line 3', 'line 4'], True)
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
from pandas.api.extensions import ExtensionArray, ExtensionDtype, register_extension_dtype, take

#: The number a missing place is stored as.
_MISSING = -1


@register_extension_dtype
class PlaceDtype(ExtensionDtype):
    """The dtype of :class:`PlaceArray`: text cells (``str``), stored as numbers."""

    name = "results_analysis.place"
    type = str
    na_value = np.nan

    @classmethod
    def construct_array_type(cls) -> type[PlaceArray]:
        return PlaceArray


class PlaceArray(ExtensionArray):
    """Row places ``"<prefix><number>"`` (one prefix per array), stored as int64 numbers."""

    def __init__(self, numbers: np.ndarray, prefix: str) -> None:
        self._numbers = np.asarray(numbers, dtype=np.int64)
        self._prefix = prefix

    @classmethod
    def lines(cls, n: int, first: int = 2) -> PlaceArray:
        """``line first`` .. ``line first+n-1``: the rows of a CSV whose header is line ``first - 1``."""
        return cls(np.arange(first, first + n, dtype=np.int64), "line ")

    # --- what pandas needs of an extension array ---------------------------------------------------------

    @property
    def dtype(self) -> PlaceDtype:
        return PlaceDtype()

    @classmethod
    def _from_sequence(cls, scalars, *, dtype=None, copy: bool = False):
        """Places from places, from their texts (``unique``, ``where``: pandas passes them back) or from missing
        values; any other text raises TypeError (pandas then keeps the column as plain text)."""
        if isinstance(scalars, cls):
            return scalars.copy() if copy else scalars
        numbers, prefixes = [], set()
        for v in scalars:
            if v is None or (not isinstance(v, str) and pd.isna(v)):
                numbers.append(_MISSING)
                continue
            head = str(v).rstrip("0123456789") if isinstance(v, str) else ""
            digits = v[len(head):] if head else ""
            if not head or not digits or head not in ("line ", "row ") or str(int(digits)) != digits:
                raise TypeError(f"{v!r} is not a row place (to write other text, take the column "
                                ".astype(object) first)")
            numbers.append(int(digits))
            prefixes.add(head)
        if len(prefixes) > 1:
            raise TypeError("row places of two kinds")
        return cls(np.array(numbers, dtype=np.int64), prefixes.pop() if prefixes else "line ")

    def __setitem__(self, key, value) -> None:
        value = value if isinstance(value, PlaceArray) else \
            type(self)._from_sequence(value if pd.api.types.is_list_like(value) else [value])
        if value._prefix != self._prefix and not value.isna().all():
            raise TypeError("row places of two kinds")
        key = pd.api.indexers.check_array_indexer(self, key)
        self._numbers[key] = value._numbers if len(value) != 1 else value._numbers[0]

    @classmethod
    def _from_factorized(cls, values, original: PlaceArray) -> PlaceArray:
        return cls(values, original._prefix)

    def _values_for_factorize(self) -> tuple[np.ndarray, int]:
        return self._numbers, _MISSING

    def _text(self, number: int) -> str | float:
        return np.nan if number == _MISSING else f"{self._prefix}{number}"

    def __getitem__(self, item: Any):
        if isinstance(item, (int, np.integer)):
            return self._text(int(self._numbers[item]))
        item = pd.api.indexers.check_array_indexer(self, item)
        return type(self)(self._numbers[item], self._prefix)

    def __len__(self) -> int:
        return len(self._numbers)

    def __iter__(self):
        for number in self._numbers.tolist():
            yield self._text(number)

    def __eq__(self, other: Any) -> np.ndarray:  # type: ignore[override]
        if isinstance(other, (pd.Series, pd.Index, pd.DataFrame)):
            return NotImplemented
        return np.asarray(self.to_numpy() == (other.to_numpy() if isinstance(other, PlaceArray) else other),
                          dtype=bool)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = np.empty(len(self), dtype=object)
        out[:] = list(self)
        return out if dtype is None or np.dtype(dtype) == object else out.astype(dtype)

    def to_numpy(self, dtype=None, copy: bool = False, na_value=pd.api.extensions.no_default) -> np.ndarray:
        out = self.__array__()
        if na_value is not pd.api.extensions.no_default:
            out[self.isna()] = na_value
        return out if dtype is None else out.astype(dtype)

    def astype(self, dtype, copy: bool = True):
        if isinstance(pd.api.types.pandas_dtype(dtype), PlaceDtype):
            return self.copy() if copy else self
        return np.asarray(self, dtype=object) if pd.api.types.pandas_dtype(dtype) == object else \
            pd.array(np.asarray(self, dtype=object)).astype(dtype, copy=False)

    @property
    def nbytes(self) -> int:
        return self._numbers.nbytes

    def isna(self) -> np.ndarray:
        return self._numbers == _MISSING

    def take(self, indices, *, allow_fill: bool = False, fill_value=None) -> PlaceArray:
        if allow_fill and not (fill_value is None or pd.isna(fill_value)):
            raise TypeError("a missing place can only be NA")
        return type(self)(take(self._numbers, indices, allow_fill=allow_fill, fill_value=_MISSING), self._prefix)

    def copy(self) -> PlaceArray:
        return type(self)(self._numbers.copy(), self._prefix)

    @classmethod
    def _concat_same_type(cls, to_concat) -> ExtensionArray:
        prefixes = {a._prefix for a in to_concat}
        if len(prefixes) == 1:
            return cls(np.concatenate([a._numbers for a in to_concat]), prefixes.pop())
        return pd.array(np.concatenate([np.asarray(a, dtype=object) for a in to_concat]), dtype=object)

    def __reduce__(self):
        return type(self), (self._numbers, self._prefix)
