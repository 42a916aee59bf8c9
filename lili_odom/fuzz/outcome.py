"""What one fuzz case ended as."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

CLEAN = "clean"  # handled: a result, a skip or a rejection that was counted
DOCUMENTED = "documented_error"  # raised the door's documented error type
OTHER = "other_exception"  # raised anything else
NONFINITE = "nonfinite_output"  # returned a non-finite pose, twist, covariance or point
INVALID = "invalid_output"  # returned a result that breaks its own contract (shape, counts)
STALLED = "stalled"  # the pipeline stopped producing output for valid input after a fault
ABORT = "native_abort"  # the worker process died (signal or exit code) inside the case
HANG = "hang"  # the case exceeded its time limit

#: Order of the report's columns.
STATUSES = (CLEAN, DOCUMENTED, OTHER, NONFINITE, INVALID, STALLED, ABORT, HANG)
#: Statuses that are findings (to fix).
FINDINGS = (OTHER, NONFINITE, INVALID, STALLED, ABORT, HANG)


@dataclass
class Outcome:
    """One case's result.

    Attributes:
        status: one of :data:`STATUSES`.
        detail: one line (exception type and message, or what was wrong).
        input: what the case fed in (one line).
        error_type: name of the exception raised, "" when none.
    """

    status: str
    detail: str = ""
    input: str = ""
    error_type: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def one_line(text: object, limit: int = 300) -> str:
    out = " ".join(str(text).split())
    return out if len(out) <= limit else out[: limit - 3] + "..."


def from_exception(exc: BaseException, documented: tuple[type, ...], input: str) -> Outcome:
    """DOCUMENTED when ``exc`` is one of ``documented`` and says something, else OTHER."""
    name = type(exc).__name__
    text = one_line(f"{name}: {exc}")
    if isinstance(exc, documented) and str(exc).strip():
        return Outcome(DOCUMENTED, text, input, name)
    return Outcome(OTHER, text, input, name)


def all_finite(*arrays) -> bool:
    """True when every given array (None skipped) holds only finite numbers."""
    for a in arrays:
        if a is None:
            continue
        if not np.all(np.isfinite(np.asarray(a, dtype=np.float64))):
            return False
    return True
