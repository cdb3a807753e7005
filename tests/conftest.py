"""Puts ``tests/`` on ``sys.path`` so every test folder imports the shared generators as ``fixtures.<name>``.

They live here, not in ``studyapp``, because a participant's installation has no use for them (the packaging
test checks the wheel leaves them out).
"""
from __future__ import annotations

import sys
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parent)
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)
