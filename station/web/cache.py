"""Rendered SVGs of the last few units (rendering a plot takes ~0.1-1 s)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable

#: What identifies a rendered SVG: (serial, what it was made from, which figure).
SvgKey = tuple[str, str, str]


class SvgCache:
    """The ``size`` most recently used SVGs, rendered once (thread-safe; two first requests may both render)."""

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._lock = threading.Lock()
        self._svgs: OrderedDict[SvgKey, str] = OrderedDict()

    def get(self, key: SvgKey, make: Callable[[], str]) -> str:
        """The SVG of ``key``, made by ``make()`` unless kept."""
        with self._lock:
            if key in self._svgs:
                self._svgs.move_to_end(key)
                return self._svgs[key]
        svg = make()
        with self._lock:
            self._svgs[key] = svg
            while len(self._svgs) > self.size:
                self._svgs.popitem(last=False)
        return svg


__all__ = ["SvgCache", "SvgKey"]
