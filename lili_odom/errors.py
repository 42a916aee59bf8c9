"""Exceptions with a message meant for the user (printed as one line by the CLI)."""


class UserError(Exception):
    """Bad input a user can fix: unreadable file, missing topic, corrupt bag, invalid parameter."""


class ThrottledWarnings:
    """Warnings that repeat per input message, logged at most once per ``period_s`` per key.

    A bad sensor can produce the same complaint 10-100 times a second; the first one is logged
    at once, the repeats within the period are counted and reported with the next one logged.

    Args:
        logger: a ``logging.Logger``.
        period_s: minimum wall time between two records of one key [s].
        clock: monotonic time source [s] (injectable for tests).
    """

    def __init__(self, logger, period_s: float = 5.0, clock=None) -> None:
        import time

        self.logger = logger
        self.period_s = float(period_s)
        self._clock = clock or time.monotonic
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def warning(self, key: str, message: str, *args) -> bool:
        """Log ``message % args`` unless ``key`` was logged less than ``period_s`` ago."""
        now = self._clock()
        last = self._last.get(key)
        if last is not None and now - last < self.period_s:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return False
        self._last[key] = now
        held = self._suppressed.pop(key, 0)
        if held:
            message = f"{message} ({held} similar in the last {self.period_s:g} s not shown)"
        self.logger.warning(message, *args)
        return True


def check_range(name: str, value, lo: float | None = None, hi: float | None = None, *,
                lo_open: bool = False, hi_open: bool = False, unit: str = "") -> None:
    """Raise ``ValueError("<name> must be <range>, got <value>")`` unless ``value`` is in range.

    ``lo``/``hi`` None mean unbounded; ``lo_open``/``hi_open`` exclude the bound. NaN and
    non-numbers are always out of range.
    """
    try:
        v = float(value)
        ok = v == v and (lo is None or (v > lo if lo_open else v >= lo)) and (
            hi is None or (v < hi if hi_open else v <= hi))
    except (TypeError, ValueError):
        ok = False
    if ok:
        return
    u = f" {unit}" if unit else ""
    if lo is not None and hi is not None:
        text = f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}{u}"
    elif lo is not None:
        text = f"{'>' if lo_open else '>='} {lo:g}{u}"
    elif hi is not None:
        text = f"{'<' if hi_open else '<='} {hi:g}{u}"
    else:
        text = "a number"
    raise ValueError(f"{name} must be {text}, got {value!r}")
