"""Stop signals: SIGINT, SIGTERM and SIGHUP become `Interrupted`, which unwinds like an error
(temporary files removed) and ends the process with 128 + the signal number. cli.run installs
the handler in the process's own entry point; a --jobs worker installs its own
(commands.pool); a conversion checks for a lost stop after every curve (commands.batch).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from typing import Any

from nurbsfeed.errors import Interrupted

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
_stopped_by = 0  # the stop signal that arrived, if one has


def stop(signum: int, frame: Any) -> None:
    """The handler of STOP_SIGNALS: unwind through every cleanup. A repeated signal (a second
    Ctrl-C) is ignored so that it cannot cut a cleanup short. An exception raised while Python
    code runs inside a callback from compiled code (numba's cache) is lost there: the conversion
    checks `_stopped_by` after every curve, and the hook keeps the lost one off stderr."""
    global _stopped_by
    _stopped_by = signum
    for other in STOP_SIGNALS:
        if signal.getsignal(other) != signal.SIG_IGN:
            signal.signal(other, _ignore)  # not SIG_IGN: one already on its way would raise
    raise Interrupted(signum)


def _ignore(signum: int, frame: Any) -> None:
    pass


def check_stopped() -> None:
    if _stopped_by:
        raise Interrupted(_stopped_by)


def _unraisable(hook_args: Any) -> None:
    """Keep a stop to its one line on stderr. A finaliser the signal cut short (llvmlite's
    ObjectRef.__del__, half detached) fails again when it is collected at exit; once a stop
    signal has arrived the run only cleans up and ends, so no such report is news."""
    if not isinstance(hook_args.exc_value, Interrupted) and not _stopped_by:
        sys.__unraisablehook__(hook_args)


def handle_stop_signals(handler: Callable[[int, Any], None]) -> None:
    sys.unraisablehook = _unraisable
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) != signal.SIG_IGN:  # nohup, a background job: stay deaf
            signal.signal(signum, handler)

