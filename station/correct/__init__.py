"""Online error reduction, the paper's Algorithm 1 (Kolhoff & Kemper), and its references.

* :class:`StreamingCorrector` - sample by sample, as the unit's firmware runs it.
* :func:`correct_batch` - the same over a whole record, vectorized (same output to rounding).
* :func:`correct_session` - Algorithm 1 over a recorded Session.
* :func:`two_sided_reference` / :func:`reference_session` - the post-processed
  counterpart (exact exponential drift, centred moving average) the paper compares with.
"""

from station.correct.batch import correct_batch
from station.correct.session_correct import (
    correct_session,
    cross_correlation,
    reference_session,
    start_index_of,
    two_sided_reference,
)
from station.correct.streaming import CHANNELS, CorrectionConstants, StreamingCorrector

__all__ = [
    "CHANNELS",
    "CorrectionConstants",
    "StreamingCorrector",
    "correct_batch",
    "correct_session",
    "cross_correlation",
    "reference_session",
    "start_index_of",
    "two_sided_reference",
]
