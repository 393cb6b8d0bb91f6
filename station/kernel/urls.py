"""URL arguments checked before anything starts: one line naming what is wrong, never a traceback.

:func:`split_url` is :func:`urllib.parse.urlsplit` with the checks every device and database URL needs
first: a length limit, no control characters, brackets that close, a port in 1..65535. The device
parsers (rig, sensor, chamber, the scheme registries) and the store call it, so ``modbus-tcp://h:99999``
and ``modbus-tcp://[::1`` are refused with the same words wherever they are given.
"""

from __future__ import annotations

from urllib.parse import SplitResult, urlsplit

from station.kernel.errors import StationError, quote_input

#: The longest URL the station takes (characters); a file path in a URL has its own OS limit as well.
MAX_URL_CHARS = 2048


class UrlError(StationError):
    """A URL argument that does not parse or names an impossible port."""


def split_url(url: str, what: str, error: type[StationError] = UrlError) -> SplitResult:
    """``url`` split, after the checks of the module docstring; raises ``error`` (one line) otherwise."""
    if not isinstance(url, str):
        raise error(f"{what} URL: expected text, got {type(url).__name__}")
    shown = quote_input(url)
    if len(url) > MAX_URL_CHARS:
        raise error(f"{what} URL {shown}: longer than {MAX_URL_CHARS} characters")
    if not url.isprintable():
        bad = next(k for k, c in enumerate(url) if not c.isprintable())
        raise error(f"{what} URL {quote_input(url, bad)}: contains a control character")
    try:
        parts = urlsplit(url)
    except ValueError as exc:
        why = "a '[' in the host is not closed by ']'" if "IPv6" in str(exc) else str(exc)
        raise error(f"{what} URL {shown}: {why}") from None
    try:
        port = parts.port
    except ValueError:
        raw = parts.netloc.rsplit("]", 1)[-1].rsplit(":", 1)[-1]
        raise error(f"{what} URL {shown}: port {quote_input(raw)} is not a number in 1..65535") from None
    if port == 0:
        raise error(f"{what} URL {shown}: port 0 (a port is 1..65535)")
    return parts


__all__ = ["MAX_URL_CHARS", "UrlError", "split_url"]
