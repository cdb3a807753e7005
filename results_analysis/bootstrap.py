"""Cluster bootstrap intervals (participants resampled whole), percentile or BCa.

A statistic is given as a function of cluster *weights*: ``stat(w)`` takes an (R, P) matrix whose row r
says how many times each of the P clusters (participants) appears in resample r, and returns the R values
of the statistic (or an (R, q) matrix of q statistics at once). Resampling whole participants keeps a
participant's correlated trials together; with participant blocks a cluster is one block.

Resamples are drawn as scipy.stats.bootstrap draws them (``rng.integers(0, P, (B, P))`` from
``numpy.random.default_rng(seed)``), so for the same seed and statistic the intervals equal scipy's.

* ``percentile``: the alpha/2 and 1 - alpha/2 quantiles (linear interpolation) of the bootstrap values.
* ``bca``: bias-corrected and accelerated (Efron & Tibshirani 1993, ch. 14.3): z0 = Phi^-1 of the share
  of bootstrap values below the estimate (ties counted half), acceleration a from the leave-one-cluster-out
  jackknife, a = sum (mean - theta_i)^3 / (6 (sum (mean - theta_i)^2)^1.5); the interval is the
  Phi(z0 + (z0 + z_q) / (1 - a (z0 + z_q))) quantiles for z_q = z_{alpha/2}, z_{1-alpha/2}. Where BCa is
  undefined (every bootstrap value on one side of the estimate, or a degenerate jackknife) the percentile
  interval is used and the row says so.

A statistic that sees the weights only through weighted sums of per-cluster rows (counts, rank sums: a
:class:`ClusterSums`) gets its jackknife from the column totals: leaving cluster i out is the totals minus
row i, so all P leave-one-out values cost O(P m) instead of P evaluations of O(P m) each. The sums are the
same numbers the weight-matrix product gives, up to the order of floating-point additions (exact for the
integer and half-integer sums the rank statistics use).

The resample counts are held as float32 (whole numbers below 2^24, so exactly), and a product of them with
per-cluster sums is computed in float32 when every product and partial sum is a multiple of a power of two
below 2^24 times it (:func:`counts_product`): then float32 holds each one exactly, the result is the exact
sum, and so the same float64 number the float64 product gives, in half the memory traffic and time (the
rank statistics' counts and half-integer rank sums always are; anything else is multiplied in float64).
"""
from __future__ import annotations

import threading
from collections.abc import Callable, Hashable, Iterator
from concurrent.futures import Future
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.special import ndtr, ndtri

INTERVALS = ("bca", "percentile")
INTERVAL_NAMES = {"bca": "BCa", "percentile": "percentile"}

#: Resamples whose weight matrix is held at once (R x P floats), to bound memory on large studies.
_CHUNK = 500
#: Cells of the weight matrix counted at once when drawing it (their counters fit in the processor's cache).
_COUNT_CELLS = 1 << 18
#: float32 holds every whole number below this exactly (24-bit significand).
_FLOAT32_EXACT = float(1 << 24)

WeightedStatistic = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ClusterSums:
    """A weighted statistic that depends on the weights w only through ``w @ sums``: ``sums`` is (P, m), one
    row of m per-cluster sums per cluster, and ``of`` maps the (R, m) weighted sums to the R values (or an
    (R, q) matrix) of the statistic. Calling it with w is ``of(w @ sums)``; :meth:`jackknife` is exact and O(P m).

    >>> x = np.array([1.0, 2.0, 4.0, 7.0])
    >>> mean = ClusterSums(np.column_stack([x, np.ones(4)]), lambda s: s[:, 0] / s[:, 1])
    >>> mean(np.ones((1, 4))).tolist(), mean.jackknife().ravel().tolist()
    ([3.5], [4.333333333333333, 4.0, 3.3333333333333335, 2.3333333333333335])
    """

    sums: np.ndarray
    of: Callable[[np.ndarray], np.ndarray]

    def __call__(self, w: np.ndarray) -> np.ndarray:
        return self.of(w @ self.sums)

    @cached_property
    def _scaled(self) -> tuple[np.ndarray, float] | None:
        """See :func:`_exact_float32`: the sums as float32 and their bound, decided once per statistic."""
        return _exact_float32(self.sums)

    def of_counts(self, counts: np.ndarray, total: float) -> np.ndarray:
        """``self(counts)`` for resample counts (whole numbers, each row summing to at most ``total``), the
        product in float32 where that is exact (see :func:`counts_product`)."""
        return self.of(counts_product(counts, self.sums, total, scaled=self._scaled))

    def jackknife(self) -> np.ndarray:
        """(P, ...) values of the statistic with each cluster left out in turn: the totals minus its row."""
        total = self.sums.sum(axis=0)
        out = [np.asarray(self.of(total[None, :] - self.sums[i:i + _CHUNK]), dtype=float)
               for i in range(0, len(self.sums), _CHUNK)]
        res = np.concatenate(out, axis=0)
        return res[:, None] if res.ndim == 1 else res

    @staticmethod
    def stack(parts: list[ClusterSums]) -> ClusterSums:
        """One statistic whose columns are the parts' values (each a 1-D statistic), in order: one product
        of the weights with every part's sums side by side."""
        edges = np.cumsum([0] + [p.sums.shape[1] for p in parts])
        sums = np.concatenate([p.sums for p in parts], axis=1)

        def of(s: np.ndarray) -> np.ndarray:
            return np.column_stack([p.of(s[:, a:b]) for p, a, b in zip(parts, edges[:-1], edges[1:])])
        return ClusterSums(sums, of)


def cluster_totals(cluster: np.ndarray, n_clusters: int, values: np.ndarray) -> np.ndarray:
    """(n_clusters, ...) sums of ``values`` (one row per block) per cluster: ``np.add.at(zeros, cluster, values)``,
    the same numbers (np.bincount adds each column's values in row order, as np.add.at does) without
    np.add.at's per-element dispatch."""
    values = np.asarray(values, dtype=float)
    flat = values.reshape(len(values), int(np.prod(values.shape[1:], dtype=np.int64)))
    out = np.empty((n_clusters, flat.shape[1]))
    for j in range(flat.shape[1]):
        out[:, j] = np.bincount(cluster, weights=flat[:, j], minlength=n_clusters)
    return out.reshape((n_clusters,) + values.shape[1:])


def _exact_float32(sums: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``sums`` as float32 and the largest resample total for which products with them are exact in float32,
    or None when they are not all multiples of 1/2 or of 1/16.

    With every value a multiple of 2^-j and counts whole, every product and every partial sum of a row's
    product is a multiple of 2^-j no larger than total * max|sums|: below 2^24 * 2^-j, float32 holds each
    one exactly, whatever the order of additions."""
    sums = np.asarray(sums, dtype=float)
    if not sums.size:
        return sums.astype(np.float32), np.inf
    top = float(np.abs(sums).max())
    if not np.isfinite(top):  # inf or NaN
        return None
    for j in (1, 4):  # halves (rank sums, counts) first: one pass over the sums in the usual case
        scaled = sums * float(1 << j)
        if np.array_equal(scaled, np.floor(scaled)):
            return sums.astype(np.float32), (_FLOAT32_EXACT / (top * (1 << j)) if top else np.inf)
    return None


def counts_product(counts: np.ndarray, sums: np.ndarray, total: float, *,
                   scaled: tuple[np.ndarray, float] | None | bool = False) -> np.ndarray:
    """``counts.astype(float) @ sums`` (float64): ``counts`` are resample counts (float32 or float64 whole
    numbers, each row summing to at most ``total``: the clusters drawn per resample). Computed in float32,
    and so exactly, when the sums allow it for that total (see :func:`_exact_float32`; ``scaled``: its
    answer, when the caller keeps it); the same numbers either way."""
    sums = np.asarray(sums, dtype=float)
    if counts.dtype == np.float32:
        if scaled is False:
            scaled = _exact_float32(sums)
        if scaled is not None and total < scaled[1]:
            return (counts @ scaled[0]).astype(np.float64)
        counts = counts.astype(np.float64)
    return counts @ sums


@dataclass(frozen=True)
class BootstrapIntervals:
    """Estimates and intervals of q statistics: arrays of shape (q,); ``method`` per statistic."""

    estimate: np.ndarray
    low: np.ndarray
    high: np.ndarray
    method: list[str]


#: (kind, clusters, seed) -> the largest weight matrix drawn so far; set only inside :func:`shared_resamples`.
_SHARED: ContextVar[dict[Hashable, np.ndarray | _Draw] | None] = ContextVar("results_analysis_shared_resamples",
                                                                    default=None)


@contextmanager
def shared_resamples() -> Iterator[None]:
    """Within this block each resample matrix (kind, clusters, seed) is drawn once and handed, read-only, to
    every caller that asks for it.

    The rows of one seeded draw are a sequence, so the first m rows of an n-row draw are the m-row draw: a
    caller asking for fewer resamples gets a prefix, bit-identical to drawing them itself. One analysis
    (each criterion's mean-rank, Bradley-Terry and effect-size intervals) thus draws each matrix once instead
    of once per criterion and statistic; the matrices are dropped when the block ends.
    """
    if _SHARED.get() is not None:  # nested: the outer block's resamples are shared with this one
        yield
        return
    token = _SHARED.set({})
    try:
        yield
    finally:
        for got in _SHARED.get().values():  # no background draw outlives the block
            if isinstance(got, _Draw):
                got.thread.join()
        _SHARED.reset(token)


def _read_only(draw: Callable[[int], np.ndarray], n_boot: int) -> np.ndarray:
    w = draw(n_boot)
    w.flags.writeable = False
    return w


class _Draw(Future):
    """A resample matrix being drawn by ``thread``."""

    def __init__(self, fn: Callable[[], np.ndarray]) -> None:
        super().__init__()
        self.thread = threading.Thread(target=self._run, args=(fn,), name="results_analysis-resamples", daemon=True)
        self.thread.start()

    def _run(self, fn: Callable[[], np.ndarray]) -> None:
        try:
            self.set_result(fn())
        except BaseException as exc:  # handed to whoever waits for the draw
            self.set_exception(exc)


def shared_draw(key: Hashable, n_boot: int, draw: Callable[[int], np.ndarray], *,
                background: bool = False) -> np.ndarray | None:
    """``draw(n_boot)`` (an (n_boot, P) matrix whose rows are a seeded sequence), read-only, taken from (or
    kept for) the enclosing :func:`shared_resamples` block.

    ``background=True`` (inside a block only) starts the draw in a thread and returns None: a later call for
    the same key waits for it. numpy's generators release the GIL while drawing, so on two cores the draw
    runs beside the analysis that does not need it yet; the matrix is the same as drawn in the foreground.
    """
    cache = _SHARED.get()
    if cache is not None and key in cache:
        got = cache[key]
        if isinstance(got, _Draw):
            got = cache[key] = got.result()
        if len(got) >= n_boot:
            return got[:n_boot]
    if background:
        if cache is not None and key not in cache:
            cache[key] = _Draw(lambda: _read_only(draw, n_boot))
        return None
    w = _read_only(draw, n_boot)
    if cache is not None:
        cache[key] = w
    return w


def resample_counts(n_clusters: int, n_boot: int, seed: int, *, background: bool = False) -> np.ndarray | None:
    """(n_boot, n_clusters) multiplicities (read-only), from the index draws scipy.stats.bootstrap makes,
    as float32 (whole numbers below 2^24, exact; float64 for 2^24 clusters or more): the matrix the rank
    statistics multiply with :func:`counts_product` (``background``: see :func:`shared_draw`)."""
    exact32 = n_clusters < _FLOAT32_EXACT

    def draw(n: int) -> np.ndarray:
        # int32 draws are the same numbers as scipy's int64 ones (numpy draws either from the same 32-bit
        # stream when the range fits in 32 bits) in half the memory: 80 MB instead of 160 for 2,000 x 10,000
        small = n_clusters <= np.iinfo(np.int32).max
        idx = np.random.default_rng(seed).integers(0, n_clusters, (n, n_clusters),
                                                   dtype=np.int32 if small else np.int64)
        out = np.empty((n, n_clusters), dtype=np.float32 if exact32 else np.float64)
        # counted a few rows at a time: no second and third (n, P) array, and the counts being incremented
        # (about 2 MB) stay in the processor's cache (a block of 500 rows of 10,000 took 4x as long)
        step = max(1, _COUNT_CELLS // max(n_clusters, 1))
        offset = (np.arange(step) * n_clusters)[:, None]
        for i in range(0, n, step):
            rows = idx[i:i + step]
            flat = (rows + offset[:len(rows)]).ravel()
            out[i:i + len(rows)] = np.bincount(flat, minlength=rows.size).reshape(len(rows), n_clusters)
        return out

    return shared_draw(("index", n_clusters, seed), n_boot, draw, background=background)


def resample_weights(n_clusters: int, n_boot: int, seed: int, *, background: bool = False) -> np.ndarray | None:
    """(n_boot, n_clusters) multiplicities as float64 (read-only), from the index draws scipy.stats.bootstrap
    makes: :func:`resample_counts` for any weighted statistic (``background``: see :func:`shared_draw`)."""
    if background:
        return resample_counts(n_clusters, n_boot, seed, background=True)
    return shared_draw(("index64", n_clusters, seed), n_boot,
                       lambda n: resample_counts(n_clusters, n, seed).astype(np.float64))


def _evaluate(stat: WeightedStatistic, w: np.ndarray) -> np.ndarray:
    out = [np.asarray(stat(w[i:i + _CHUNK]), dtype=float) for i in range(0, len(w), _CHUNK)]
    res = np.concatenate(out, axis=0)
    return res[:, None] if res.ndim == 1 else res


def _evaluate_counts(stat: WeightedStatistic, counts: np.ndarray, n_clusters: int) -> np.ndarray:
    """:func:`_evaluate` on resample counts: a :class:`ClusterSums` multiplies them in float32 where that is
    exact; any other statistic gets them as float64, a chunk at a time."""
    if isinstance(stat, ClusterSums):
        out = [np.asarray(stat.of_counts(counts[i:i + _CHUNK], n_clusters), dtype=float)
               for i in range(0, len(counts), _CHUNK)]
    else:
        out = [np.asarray(stat(counts[i:i + _CHUNK].astype(np.float64)), dtype=float)
               for i in range(0, len(counts), _CHUNK)]
    res = np.concatenate(out, axis=0)
    return res[:, None] if res.ndim == 1 else res


def _jackknife(stat: WeightedStatistic, n_clusters: int) -> np.ndarray:
    """The statistic with each cluster left out in turn: from the column totals for a :class:`ClusterSums`,
    else by evaluating it on weight rows built a chunk at a time (a P x P matrix of a large study would not
    fit in memory)."""
    if isinstance(stat, ClusterSums):
        return stat.jackknife()
    out = []
    for i in range(0, n_clusters, _CHUNK):
        w = np.ones((min(_CHUNK, n_clusters - i), n_clusters))
        w[np.arange(w.shape[0]), i + np.arange(w.shape[0])] = 0.0
        res = np.asarray(stat(w), dtype=float)
        out.append(res[:, None] if res.ndim == 1 else res)
    return np.concatenate(out, axis=0)


def cluster_bootstrap(stat: WeightedStatistic, n_clusters: int, *, n_boot: int = 2000, ci: float = 0.95,
                      seed: int = 0, method: str = "bca") -> BootstrapIntervals:
    """Estimate and ``ci`` interval of each statistic ``stat`` returns, resampling clusters (seeded).

    >>> x = np.array([1.0, 2.0, 4.0, 7.0, 11.0])
    >>> mean = lambda w: (w @ x) / w.sum(axis=1)
    >>> r = cluster_bootstrap(mean, 5, n_boot=999, seed=1, method="percentile")
    >>> float(r.estimate[0]), bool(r.low[0] < 5 < r.high[0])
    (5.0, True)
    """
    if method not in INTERVALS:
        raise ValueError(f"unknown bootstrap interval {method!r}: one of {', '.join(INTERVALS)}")
    est = _evaluate(stat, np.ones((1, n_clusters)))[0]
    q = est.size
    if n_boot <= 0 or n_clusters < 2:
        nan = np.full(q, np.nan)
        return BootstrapIntervals(est, nan, nan.copy(), ["none"] * q)
    boot = _evaluate_counts(stat, resample_counts(n_clusters, n_boot, seed), n_clusters)  # (B, q)
    alpha = (1.0 - ci) / 2.0
    levels = np.tile([alpha, 1.0 - alpha], (q, 1))
    names = [INTERVAL_NAMES["percentile"]] * q
    if method == "bca":
        jack = _jackknife(stat, n_clusters)  # (P, q), leave one cluster out
        with np.errstate(divide="ignore", invalid="ignore"):
            share = ((boot < est).sum(axis=0) + (boot <= est).sum(axis=0)) / (2.0 * len(boot))
            z0 = ndtri(share)
            u = jack.mean(axis=0) - jack
            a = (u ** 3).sum(axis=0) / (6.0 * ((u ** 2).sum(axis=0)) ** 1.5)
            for col in range(q):
                if np.isfinite(z0[col]) and np.isfinite(a[col]):
                    zs = z0[col] + ndtri(np.array([alpha, 1.0 - alpha]))
                    levels[col] = ndtr(z0[col] + zs / (1.0 - a[col] * zs))
                    names[col] = INTERVAL_NAMES["bca"]
                else:
                    names[col] = "percentile (BCa undefined)"
    low = np.array([np.quantile(boot[:, c], levels[c, 0]) if np.isfinite(boot[:, c]).all() else np.nan
                    for c in range(q)])
    high = np.array([np.quantile(boot[:, c], levels[c, 1]) if np.isfinite(boot[:, c]).all() else np.nan
                     for c in range(q)])
    return BootstrapIntervals(est, low, high, names)
