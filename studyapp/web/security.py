"""The server's security rules, each in one place: response headers, rate limits, request checks.

* Every response carries :data:`SECURITY_HEADERS`: a Content-Security-Policy that allows only the server's own
  scripts, styles and media (no inline script, no framing: ``frame-ancestors 'none'``), ``nosniff``,
  ``Referrer-Policy: no-referrer`` (a participant's page address holds their session token: it must not leave
  with a link), and ``Cache-Control: no-store`` on everything but the static assets.
* :class:`RateLimiter`: a token bucket per client and kind of request (participant actions, new
  participants, experimenter logins); over the limit a request gets 429.
* A state-changing request must be JSON (``Content-Type: application/json``, which a cross-site form cannot
  send), carry the participant's CSRF token in ``X-CSRF-Token`` and, when the browser says where it comes
  from (``Origin``), come from this server (:func:`same_origin`).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from typing import Any

CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; media-src 'self'; "
       "connect-src 'self'; form-action 'self'; base-uri 'none'; frame-ancestors 'none'")
SECURITY_HEADERS = {
    "content-security-policy": CSP,
    "x-content-type-options": "nosniff",
    "referrer-policy": "no-referrer",
    "x-frame-options": "DENY",
    "cross-origin-opener-policy": "same-origin",
    "cross-origin-resource-policy": "same-origin",
    "permissions-policy": "camera=(), microphone=(), geolocation=()",
}
#: The largest request body the server reads (a questionnaire with long comments fits many times over).
MAX_BODY_BYTES = 64 * 1024


@dataclass
class Bucket:
    tokens: float
    stamp: float


@dataclass
class RateLimiter:
    """At most ``burst`` requests at once and ``per_s`` per second on average, per key.

    >>> r = RateLimiter(per_s=1.0, burst=2, clock=lambda: 0.0)
    >>> [r.allow("ip") for _ in range(3)]
    [True, True, False]
    """

    per_s: float
    burst: int
    clock: Any = time.monotonic
    _buckets: dict[str, Bucket] = field(default_factory=dict)

    def allow(self, key: str) -> bool:
        now = self.clock()
        b = self._buckets.get(key)
        if b is None:
            if len(self._buckets) > 100_000:   # forget idle clients rather than grow without bound
                self._buckets.clear()
            b = self._buckets[key] = Bucket(float(self.burst), now)
        b.tokens = min(float(self.burst), b.tokens + (now - b.stamp) * self.per_s)
        b.stamp = now
        if b.tokens >= 1.0:
            b.tokens -= 1.0
            return True
        return False


def same_origin(origin: str | None, host: str | None, scheme: str) -> bool:
    """Whether a request's ``Origin`` header is this server (a missing header is accepted: old browsers
    and same-origin GETs send none; the CSRF token is the real check).

    >>> same_origin("https://study.example.org", "study.example.org", "https")
    True
    >>> same_origin("https://evil.example", "study.example.org", "https"), same_origin("null", "a", "http")
    (False, False)
    """
    if origin is None:
        return True
    return bool(host) and origin in (f"{scheme}://{host}", f"https://{host}", f"http://{host}")


class BadRequest(ValueError):
    """A request that breaks a rule of the protocol (the message is for the log, not for participants)."""


def parse_json(body: bytes) -> dict[str, Any]:
    """A request body as a JSON object, refused when too large, not JSON, not an object or holding a number
    that is not finite."""
    if len(body) > MAX_BODY_BYTES:
        raise BadRequest(f"request body over {MAX_BODY_BYTES} bytes")
    try:
        data = json.loads(body.decode("utf-8"), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError) as exc:
        raise BadRequest(f"not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise BadRequest("the body must be a JSON object")
    return data


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is not a number")


def finite_number(value: Any, lo: float, hi: float) -> float | None:
    """``value`` as a float when it is a finite number in ``[lo, hi]``, else None.

    >>> finite_number(3, 0, 10), finite_number(float("nan"), 0, 10), finite_number("3", 0, 10)
    (3.0, None, None)
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    x = float(value)
    return x if math.isfinite(x) and lo <= x <= hi else None
