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

import threading

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


_ONE_DIGIT, _UP, _SLOW, _BAD = 128, 22, 100, 127
_CODES: dict[int, np.ndarray] = {}
_CODES_LOCK = threading.Lock()


def _exponent_codes(nf: int) -> np.ndarray:
    """For ``nf`` fraction digits: a code per exponent key (byte 0: first digit, byte 1: second digit or the
    space after one digit, bit 16: a minus sign). Low 7 bits: the divisor's index in :data:`_POW10` (``nf``
    minus the exponent, 0 to 22), or :data:`_UP` plus the multiplier's index (1 to 22), or :data:`_SLOW` for
    a power of ten beyond the exact range, or :data:`_BAD` when the bytes are not an exponent; plus
    :data:`_ONE_DIGIT` for a one-digit exponent."""
    with _CODES_LOCK:  # parsing threads share one table per layout
        if nf not in _CODES:
            # keys as (minus, byte 1, byte 0) on a broadcast grid: small int16 temporaries
            d1 = np.arange(256, dtype=np.int16)
            d2, minus = d1[:, None], np.arange(2, dtype=np.int16)[:, None, None]
            digit1, digit2 = (d1 >= 48) & (d1 <= 57), (d2 >= 48) & (d2 <= 57)
            one = digit1 & (d2 <= 32)
            exponent = np.where(digit2, 10 * (d1 - 48) + d2 - 48, d1 - 48) * (1 - 2 * minus)
            index = nf - exponent
            code = np.where((index >= 0) & (index <= 22), index,
                            np.where((index < 0) & (index >= -22), _UP - index, _SLOW)) + np.where(one, _ONE_DIGIT, 0)
            _CODES[nf] = np.where(digit1 & (digit2 | one), code, _BAD).astype(np.uint8).ravel()
        return _CODES[nf]


def _layout(buf: np.ndarray, first_dot: int) -> tuple[int, bool] | None:
    """(fraction digits, has exponent) of the token whose point is at ``first_dot``."""
    tail = bytes(buf[first_dot + 1 : first_dot + 12])
    nf = len(tail) - len(tail.lstrip(b"0123456789"))
    if nf > 8:
        return None
    return nf, tail[nf : nf + 1] in (b"e", b"E")


def parse_block(text: bytes, n_columns: int) -> tuple[np.ndarray, int] | None:
    """``(lines, n_columns)`` float64 values of ``text`` (whole lines; the last may lack its line end) and the
    count of its line ends, or ``None`` when the text is not in an accepted layout or anything in it is
    wrong."""
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
    widths = np.bitwise_count(run)  # integer digits per token
    int_digits, widest = int(widths.sum()), int(widths.max())
    np.right_shift(a, _U(8), out=b)
    b ^= a  # high bit of the lead byte alone (none when the 7 bytes are digits)
    # the lead byte is a sign or not; whatever else it is stays out of the token, and the byte count below
    # refuses the piece (a sign after a non-space byte likewise: no token can hold that byte)
    one = np.right_shift(b, _U(7), out=b)  # 0x01 at the lead byte
    np.multiply(one, _U(0xFF), out=c)
    c &= x
    np.multiply(one, _U(0x2D ^ 0x30), out=a)
    minus = c == a
    np.multiply(one, _U(0x2B ^ 0x30), out=a)
    signed = c == a
    signed |= minus
    if nf == 0 and not run.all():  # "." or "-.": no digit at all
        return None
    np.right_shift(run, _U(7), out=b)
    del run  # (memory: each parsing thread holds a few arrays of one word per token)
    b *= _U(0xFF)
    x &= b  # the integer digits' values at bytes 6 and down, nothing else

    # fraction: nf digits right after the point; with the integer digits, one integer of up to 8 digits when
    # they fit (``%e``: always), else two
    np.bitwise_xor(words[:, 1], _X30, out=a)
    if nf:
        _non_digits(a, b, c)
        b <<= _U(64 - 8 * nf)
        if b.max():
            return None
        np.left_shift(a, _U(64 - 8 * nf), out=c)
        if widest <= 8 - nf:
            x >>= _U(8 * (nf - 1))
            x |= c
            mant = _eight_digits(x)
        else:
            x <<= _U(8)
            mant = _eight_digits(x)
            mant *= _U(10**nf)
            mant += _eight_digits(c)
    else:
        x <<= _U(8)
        mant = _eight_digits(x)
    # the 8 bytes after the fraction, byte 0 first: the token's end or its exponent
    if nf:
        np.right_shift(words[:, 1], _U(8 * nf), out=c)
        np.left_shift(words[:, 2], _U(64 - 8 * nf), out=b)
        c |= b
    else:
        c[:] = words[:, 1]
    del windows, words
    values = mant.astype(np.float64)
    if not has_exp:
        c &= _U(0xFF)
        if c.max() > 32:
            return None
        exp_bytes = 0
        if nf:
            values /= _POW10[nf]
    else:
        # 'e' or 'E', a sign, one or two digits (one: DiffSHEG's cut last number of a line)
        np.bitwise_and(c, _U(0xFFFF), out=a)
        a |= _U(0x20)
        e_sign = a == _U(0x2D65)
        e_sign |= a == _U(0x2B65)
        if not e_sign.all():
            return None
        # after two digits, a space (the table below checks the byte after one digit)
        np.right_shift(c, _U(32), out=b)
        b &= _U(0xFF)
        ends = b <= _U(32)
        # the two bytes after the sign, and the sign's 0x04 bit ('-' has it, '+' not) as bit 16
        np.right_shift(c, _U(16), out=a)
        a &= _U(0xFFFF)
        c <<= _U(6)
        c &= _U(0x10000)
        a |= c
        code = _exponent_codes(nf).take(a.view(np.int64))
        one_digit = code >= _ONE_DIGIT
        ends |= one_digit
        if not ends.all():
            return None
        exp_bytes = 4 * n - int(np.count_nonzero(one_digit))
        code &= np.uint8(_ONE_DIGIT - 1)
        slow = ()
        if code.max() > 22:
            if code.max() == _BAD:
                return None
            slow = np.flatnonzero(code == _SLOW)
            if slow.size > _MAX_SLOW_SHARE * n:
                return None
            code[slow] = 0  # float() reads these below
            up = np.flatnonzero(code > 22)
            values[up] *= _POW10.take(code[up] - _UP)
            code[up] = 0
        values /= _POW10.take(code)
        for k in list(slow):
            d = int(dots[k])
            start = d - int(widths[k]) - int(signed[k])
            token = bytes(buf[start : start + _WIDTH + 8]).split()[0]
            exp_bytes += len(token) - (d - start) - 1 - nf - (3 if one_digit[k] else 4)  # as counted above
            try:
                values[k] = abs(float(token))
            except ValueError:
                return None

    # the tokens found cover every non-space byte: no token without a point, no stray byte
    if n * (1 + nf) + int_digits + int(np.count_nonzero(signed)) + exp_bytes != non_space:
        return None
    bits = values.view(_U)
    sign = minus.view(np.uint8).astype(_U)
    sign <<= _U(63)
    bits |= sign  # the sign (-0.0 stays negative)
    return values.reshape(n // n_columns, n_columns), newlines.size
