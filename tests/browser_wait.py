"""Waiting in the browser tests for a condition of the page, under the pages' Content Security Policy.

Playwright's ``page.wait_for_function`` compiles its string predicate with ``eval`` inside the page, which the
station's CSP (no 'unsafe-eval') forbids, as it should. :func:`wait_for` polls the expression from the test with
``page.evaluate`` instead (evaluated through the browser's DevTools protocol, not by the page's scripts), so the
pages are tested under the policy they ship with.
"""

from __future__ import annotations

import time


def wait_for(page: object, expression: str, timeout: float = 30_000, interval_ms: float = 100) -> None:
    """Return once ``expression`` (JavaScript) is truthy in ``page``; AssertionError after ``timeout`` ms."""
    deadline = time.monotonic() + timeout / 1000.0
    while True:
        if page.evaluate(expression):  # type: ignore[attr-defined]
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout / 1000:g} s waiting for: {expression}")
        page.wait_for_timeout(interval_ms)  # type: ignore[attr-defined]
