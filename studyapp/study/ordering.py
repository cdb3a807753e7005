"""Balanced orders: Williams Latin squares for clip order, balanced slot permutations for the three models.

Clip order (``[ordering] method``):

* ``balanced-latin-square``: a Williams design over the rotation stimuli. Row ``r`` of the square is the
  order of participant row ``r``; every stimulus appears once per position in each block of rows and every
  ordered pair of stimuli is adjacent equally often (first-order carry-over balance).
* ``random``: a permutation seeded by (design seed, participant id).
* ``fixed``: the order of ``[[stimuli]]`` in the design.

Slot assignment (``[slots] assignment``), three conditions in three slots:

* ``balanced``: the 6 permutations split into the 3 even ones (cyclic shifts, a Latin square) and the 3 odd
  ones (another Latin square). A participant's trials go in blocks of 3; each block uses the rows of one of
  the two squares, the squares alternate, so after any number of trials every condition has been in every
  slot equally often give or take one. Participant index ``k`` shifts both the square (``k mod 2``) and the
  row within it (``k mod 3``): by the Chinese remainder theorem any 6 consecutive participants see all 6
  permutations exactly once at every trial position.
* ``random``: each trial's permutation drawn at random, seeded by (design seed, participant id).
"""
from __future__ import annotations

import hashlib
from itertools import permutations
from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from studyapp.study.design import Design

#: The three even permutations (rows of the cyclic Latin square) then the three odd ones.
EVEN_PERMS: tuple[tuple[int, int, int], ...] = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
ODD_PERMS: tuple[tuple[int, int, int], ...] = ((0, 2, 1), (2, 1, 0), (1, 0, 2))
ALL_PERMS: tuple[tuple[int, int, int], ...] = tuple(permutations(range(3)))


def williams_square(n: int) -> np.ndarray:
    """The Williams balanced Latin square for ``n`` treatments.

    First row ``0, 1, n-1, 2, n-2, ...``; row ``r`` adds ``r`` (mod n). Even ``n``: ``n`` rows, each ordered
    pair adjacent exactly once. Odd ``n``: ``2n`` rows, the ``n`` rows followed by each of them reversed,
    each ordered pair adjacent exactly twice. In both cases every block of ``n`` rows is a Latin square.

    >>> williams_square(4).tolist()
    [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    >>> williams_square(3).shape
    (6, 3)
    """
    if n < 1:
        raise ValueError(f"a Latin square needs at least one treatment, got n={n}")
    first = [0]
    lo, hi = 1, n - 1
    for i in range(1, n):
        if i % 2:
            first.append(lo)
            lo += 1
        else:
            first.append(hi)
            hi -= 1
    square = (np.asarray(first)[None, :] + np.arange(n)[:, None]) % n
    if n % 2 and n > 1:
        square = np.concatenate([square, square[:, ::-1]], axis=0)
    return square.astype(np.int64)


def n_latin_rows(n: int) -> int:
    """Number of rows of the Williams square for ``n`` treatments (``n`` even, ``2n`` odd, 1 for n <= 1)."""
    return 1 if n <= 1 else (n if n % 2 == 0 else 2 * n)


def participant_seed(design_seed: int, participant_id: str, stream: str = "") -> int:
    """A 63-bit seed from the design seed and the participant id, the same on every machine and run.

    Python's ``hash()`` is salted per process, so a digest is used instead.

    >>> participant_seed(1, "P01") == participant_seed(1, "P01") != participant_seed(1, "P02")
    True
    """
    digest = hashlib.sha256(f"{int(design_seed)}\0{participant_id}\0{stream}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def latin_row(design: "Design", row: int, participant_id: str | None = None, ids: Sequence[str] | None = None,
              stream: str = "order") -> list[str]:
    """Order of the rotation stimuli (ids; or of ``ids``, a block's stimuli) for one design row.

    ``balanced-latin-square`` uses Williams row ``row mod n_rows``; ``fixed`` the design order; ``random``
    a permutation seeded by (design seed, ``participant_id``, ``stream``), falling back to the row when no id
    is given.
    """
    ids = design.rotation_stimuli if ids is None else list(ids)
    if design.ordering == "fixed" or len(ids) <= 1:
        return list(ids)
    if design.ordering == "random":
        key = participant_id if participant_id is not None else f"row{row}"
        rng = np.random.default_rng(participant_seed(design.seed, key, stream))
        return [ids[i] for i in rng.permutation(len(ids))]
    square = williams_square(len(ids))
    return [ids[i] for i in square[row % len(square)]]


def slot_permutations(n_trials: int, rng_seed: int, participant_index: int, mode: str) -> list[tuple[int, int, int]]:
    """Which condition goes to which slot, trial by trial: ``perm[s]`` is the condition index in slot ``s``.

    ``balanced``: blocks of three trials, each block the rows of one 3x3 Latin square (even and odd
    permutations alternate), shifted by ``participant_index`` (see the module notes); ``rng_seed`` is not
    used. ``random``: independent uniform draws from ``rng_seed``.

    >>> slot_permutations(4, 0, 0, "balanced")
    [(0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1)]
    >>> slot_permutations(2, 0, 1, "balanced")
    [(2, 1, 0), (1, 0, 2)]
    """
    if n_trials < 0:
        raise ValueError(f"n_trials must be >= 0, got {n_trials}")
    if mode == "random":
        rng = np.random.default_rng(rng_seed)
        return [ALL_PERMS[i] for i in rng.integers(0, 6, size=n_trials)]
    if mode != "balanced":
        raise ValueError(f"unknown slot assignment mode {mode!r} (balanced or random)")
    k = int(participant_index)
    out = []
    for t in range(n_trials):
        block, pos = divmod(t, 3)
        square = EVEN_PERMS if (block + k) % 2 == 0 else ODD_PERMS
        out.append(square[(pos + k) % 3])
    return out
