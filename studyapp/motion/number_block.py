"""Whitespace-separated decimal numbers in the layouts BVH writers use -> float64, vectorized over raw bytes.

:func:`parse_block` reads a piece of whole frame lines into a ``(lines, n_columns)`` array with a fixed number
of numpy operations per piece, no Python object per number, and values **identical to Python's**
``float(token)`` (correctly rounded). It accepts only what it can read exactly and returns ``None`` for
anything else, so that its caller reads that piece with a general parser, which also names any error.

Accepted (every token of the piece): ``[+-]D[D...].F...[(e|E)(+|-)X[X[X]]]`` where

* ``D`` are up to 6 integer digits, 5 after a sign (any mix of signs and widths; none is ``.5``);
* the fraction has the same number ``nf`` (0 to 8) of digits in every token of the piece (``%.6f``, ``%e``,
  ``%.4f`` writers);
* the exponent, when the piece's first token has one, is in every token, with a sign and 1 or 2 digits
  (``%e``; DiffSHEG cuts the last digit of a line's last number: ``e+0``);
* tokens are separated by spaces, tabs, ``\\r\\n`` or ``\\n``; a line holds ``n_columns`` tokens or none.

Exactness (Clinger's fast path): the digits form an integer ``M = int * 10**nf + frac`` below ``10**14``
(< 2**53, so exact as a double) and the value is ``M * 10**p`` with ``p = exponent - nf``; for ``|p| <= 22``
``10**|p|`` is exact too, so one IEEE multiplication or division gives the correctly rounded value, which is
what ``float()`` returns. The few tokens with ``|p| > 22`` (values below about 1e-16) go through ``float()``.

How: the byte offsets of the decimal points (``np.flatnonzero``) locate the tokens; one gather takes the 24
bytes around each point as three 64-bit words; digits are classified and converted eight bytes at a time
(SWAR: a digit test by one addition per word, eight ASCII digits to an integer in three multiply-shift
steps). Checks of each token's bytes and boundaries, of the byte classes of the piece and of its count of
non-space bytes prove that the tokens found cover the piece exactly, so nothing is skipped or misread.
"""
from __future__ import annotations

import numpy as np

__all__ = ["parse_block"]

_U = np.uint64
#: Space bytes put before and after the text (the 24-byte windows may reach past its ends).
PAD = 32
_LEFT, _WIDTH = 7, 24  # bytes gathered around each point: 7 before it, the point, 16 after


def _each(byte: int) -> np.uint64:
    return _U(int.from_bytes(bytes([byte]) * 8, "little"))


_X30, _X7F, _X76, _X80, _X0F = (_each(b) for b in (0x30, 0x7F, 0x76, 0x80, 0x0F))
_LOW7_80 = _U(0x0080808080808080)  # high bits of bytes 0-6 (byte 7 of the left word is the point)
_POW10 = np.array([10.0 ** k for k in range(23)])  # exact doubles
#: Share of tokens whose power of ten is beyond 1e22 (read by ``float()``) above which the piece goes back.
_MAX_SLOW_SHARE = 0.01


def _non_digits(x: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """High bit of each byte of ``out`` set where that byte of ``x ^ 0x30..`` (``x``: bytes XOR '0') is not
    0-9: ``(x & 0x7F) + 0x76`` carries into the high bit from 10 up, and never into the next byte."""
    np.bitwise_and(x, _X7F, out=tmp)
    np.add(tmp, _X76, out=tmp)
    np.bitwise_or(tmp, x, out=out)
    np.bitwise_and(out, _X80, out=out)
    return out


def _eight_digits(v: np.ndarray) -> np.ndarray:
    """In place: words whose bytes are digit values 0-9 (byte 0 the most significant) -> their integers."""
    v *= _U(2561)
    v >>= _U(8)
    v &= _U(0x00FF00FF00FF00FF)
    v *= _U(6553601)
    v >>= _U(16)
    v &= _U(0x0000FFFF0000FFFF)
    v *= _U(42949672960001)
    v >>= _U(32)
    return v


def _layout(buf: np.ndarray, first_dot: int) -> tuple[int, bool] | None:
    """(fraction digits, has exponent) of the token whose point is at ``first_dot``."""
    tail = bytes(buf[first_dot + 1 : first_dot + 12])
    nf = len(tail) - len(tail.lstrip(b"0123456789"))
    if nf > 8:
        return None
    return nf, tail[nf : nf + 1] in (b"e", b"E")


def parse_block(text: bytes, n_columns: int) -> np.ndarray | None:
    """``(lines, n_columns)`` float64 values of ``text`` (whole lines; the last may lack its line end), or
    ``None`` when the text is not in an accepted layout or anything in it is wrong."""
    size = len(text)
    if n_columns <= 0 or not size:
        return None
    buf = np.empty((size + 2 * PAD + 7) // 8 * 8, dtype=np.uint8)
    buf[:PAD] = 32
    buf[PAD : PAD + size] = np.frombuffer(text, dtype=np.uint8)
    buf[PAD + size :] = 32
    dots = np.flatnonzero(buf == 46)
    n = dots.size
    if n == 0 or n % n_columns:
        return None
    layout = _layout(buf, int(dots[0]))
    if layout is None:
        return None
    nf, has_exp = layout

    # bytes below 32 other than \t \n \r are refused; a \r must end a line (the general parser's line rules)
    newlines = np.flatnonzero(buf == 10)
    controls = int(np.count_nonzero(buf < 32))
    if controls != newlines.size:
        crs = np.flatnonzero(buf == 13)
        if not np.all(buf[crs + 1] == 10) or controls != newlines.size + crs.size + int(np.count_nonzero(buf == 9)):
            return None
    # each line holds n_columns points or none: no line end inside a group of n_columns points, one between
    # groups (a token without a point fails the byte count below)
    group_start = np.searchsorted(newlines, dots[::n_columns])
    group_end = np.searchsorted(newlines, dots[n_columns - 1 :: n_columns])
    if np.any(group_start != group_end) or np.any(group_start[1:] == group_end[:-1]):
        return None
    non_space = buf.size - int(np.count_nonzero(buf <= 32))

    windows = np.ndarray((buf.size - _WIDTH,), dtype=f"V{_WIDTH}", buffer=buf, strides=(1,))[dots - _LEFT]
    words = windows.view(_U).reshape(n, 3)
    a, b, c = np.empty(n, _U), np.empty(n, _U), np.empty(n, _U)

    # integer part: the digits between the last non-digit before the point and the point
    x = np.bitwise_xor(words[:, 0], _X30)  # digit bytes now hold 0-9; byte 7 is the point
    _non_digits(x, a, b)
    a &= _LOW7_80
    for k in (8, 16, 32):  # smear the highest non-digit down: a's bytes up to the lead byte are marked
        np.right_shift(a, _U(k), out=b)
        a |= b
    run = np.bitwise_xor(a, _LOW7_80)  # high bits of the integer digits
    int_digits = int(np.bitwise_count(run).sum())
    np.right_shift(a, _U(8), out=b)
    b ^= a  # high bit of the lead byte (a space or a sign) alone
    # its byte, compared with a space, '-' and '+' put at its place
    one = np.right_shift(b, _U(7))  # 0x01 at the lead byte
    raw = np.bitwise_xor(x, _X30)
    lead = np.multiply(one, _U(0xFF), out=c)
    lead &= raw
    np.multiply(one, _U(0x20), out=a)
    space = lead <= a
    np.multiply(one, _U(0x2D), out=a)
    minus = lead == a
    np.multiply(one, _U(0x2B), out=a)
    signed = lead == a
    signed |= minus
    # before a sign, a space: the byte below the lead byte, which must lie in the window
    one >>= _U(8)
    np.multiply(one, _U(0xFF), out=a)
    a &= raw
    one *= _U(0x20)
    signed &= a <= one
    signed &= b > _U(0x80)
    space &= b != _U(0)
    space |= signed
    if not space.all():
        return None
    if nf == 0 and not run.all():  # "." or "-.": no digit at all
        return None
    np.right_shift(run, _U(7), out=b)
    b *= _U(0xFF)
    x &= b
    x <<= _U(8)
    mant = _eight_digits(x)

    # fraction: nf digits right after the point
    np.bitwise_xor(words[:, 1], _X30, out=a)
    if nf:
        _non_digits(a, b, c)
        b <<= _U(64 - 8 * nf)
        if b.max():
            return None
        mant *= _U(10**nf)
        np.left_shift(a, _U(64 - 8 * nf), out=c)
        mant += _eight_digits(c)
    # the 8 bytes after the fraction, byte 0 first: the token's end or its exponent
    if nf:
        np.right_shift(words[:, 1], _U(8 * nf), out=c)
        np.left_shift(words[:, 2], _U(64 - 8 * nf), out=b)
        c |= b
    else:
        c[:] = words[:, 1]
    values = mant.astype(np.float64)
    if not has_exp:
        c &= _U(0xFF)
        if c.max() > 32:
            return None
        exp_bytes = 0
        if nf:
            values /= _POW10[nf]
    else:
        # 'e' or 'E', a sign, one or two digits, a space
        np.bitwise_and(c, _U(0xFFFF), out=a)
        a |= _U(0x20)
        e_minus = a == _U(0x2D65)
        e_sign = a == _U(0x2B65)
        e_sign |= e_minus
        if not e_sign.all():
            return None
        # two digits then a space (one digit: DiffSHEG's cut last number of a line, fixed up below)
        np.right_shift(c, _U(16), out=a)
        a ^= _X30
        np.bitwise_and(a, _U(0xFFFF), out=b)
        _non_digits(b, b, c)
        short = np.flatnonzero(b)
        np.right_shift(a, _U(16), out=c)
        c &= _U(0xFF)
        c ^= _U(0x30)  # the byte after two digits
        if short.size:
            c[short] = (a[short] >> _U(8)) & _U(0xFF) ^ _U(0x30)
            if b[short].max() > 0x8000 or b[short].min() < 0x8000:  # the second byte alone is not a digit
                return None
            a[short] &= _U(0xFF)  # the formula below then gives 10 * digit
        if c.max() > 32:
            return None
        a &= _U(0x0F0F)
        a *= _U(2561)
        a >>= _U(8)
        a &= _U(0xFF)  # 10 * first + second digit
        exponent = a.astype(np.int64)
        if short.size:
            exponent[short] //= 10
        exp_bytes = 4 * n - short.size
        np.negative(exponent, out=exponent, where=e_minus)
        exponent -= nf  # the power of ten of the integer mant
        low, high = int(exponent.min()), int(exponent.max())
        slow = np.flatnonzero((exponent < -22) | (exponent > 22)) if low < -22 or high > 22 else ()
        if len(slow) > _MAX_SLOW_SHARE * n:
            return None
        if high > 0:
            up = np.flatnonzero(exponent > 0)
            values[up] *= _POW10.take(np.minimum(exponent[up], 22))
            exponent[up] = 0
        np.negative(exponent, out=exponent)
        np.minimum(exponent, 22, out=exponent)
        values /= _POW10.take(exponent)
        for k in list(slow):
            d = int(dots[k])
            start = d - int(np.bitwise_count(run[k])) - int(signed[k])
            values[k] = abs(float(bytes(buf[start : start + _WIDTH + 8]).split()[0]))

    # the tokens found cover every non-space byte: no token without a point, no stray byte
    if n * (1 + nf) + int_digits + int(np.count_nonzero(signed)) + exp_bytes != non_space:
        return None
    bits = values.view(_U)
    bits |= minus.view(np.uint8).astype(_U) << _U(63)  # the sign (-0.0 stays negative)
    return values.reshape(n // n_columns, n_columns)
