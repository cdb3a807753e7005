"""Fixtures for the scripted participants' tests: the tiny studies the UI tests use too."""
from __future__ import annotations

from fixtures.studies import secrets_of, tied_study, tiny_study  # noqa: F401
