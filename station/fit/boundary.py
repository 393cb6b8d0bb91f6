"""The boundary of the numerics: a failure inside numpy, scipy or LAPACK becomes a one-line FitError.

Inputs are checked before they reach the numerics (:mod:`station.fit.checks`,
:mod:`station.fit.consistency`), so LAPACK never sees a NaN and prints nothing. What still goes
wrong inside (a singular system, a non-converging decomposition, an overflow) is reported as
:class:`~station.kernel.errors.FitError` naming what was being fitted, never as a traceback.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from station.kernel.errors import FitError

#: exceptions numpy, scipy and LAPACK raise on numbers they cannot handle
NUMERIC_ERRORS: tuple[type[BaseException], ...] = (
    ArithmeticError, ValueError, np.linalg.LinAlgError, IndexError,
)


@contextmanager
def numerics(what: str) -> Iterator[None]:
    """Turn a numerical failure inside the block into ``FitError("<what>: ...")``."""
    try:
        with np.errstate(all="ignore"):
            yield
    except FitError:
        raise
    except NUMERIC_ERRORS as exc:
        detail = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise FitError(f"{what}: numerical failure ({detail}); the recording cannot be fitted") from exc
