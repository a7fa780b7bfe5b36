"""The command line: the click group `main` of the commands (nurbsfeed.commands, a module each)
and `run`, the console script. It and the commands are the only code that imports click,
prints, and picks exit codes.

Every command is thin: parse options, call the pipeline or an analysis, print its report. Errors
from the core (NurbsfeedError) become `FILE:LINE:COL: message` on stderr with the exit code from
errors.py and no traceback (commands.common.reports_errors). SIGINT, SIGTERM and SIGHUP become
`Interrupted`, which unwinds like an error (temporary files removed) and ends the process with
128 + the signal number (commands.stops).
"""

from __future__ import annotations

import gc
import os
import signal
import sys

import click

from nurbsfeed import __version__
from nurbsfeed.commands.analyses import check, compare, plot
from nurbsfeed.commands.convert import convert
from nurbsfeed.commands.plan import plan
from nurbsfeed.commands.progress import watch_compiling
from nurbsfeed.commands.stops import handle_stop_signals, stop
from nurbsfeed.commands.warm_up import WarmUp
from nurbsfeed.errors import Interrupted


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="nurbsfeed")
def main() -> None:
    """Plan a jerk-limited feed along NURBS toolpaths and write densified G1 moves."""


for command in (convert, plan, compare, check, plot):
    main.add_command(command)


def run() -> None:
    """The console script: `main` in a process that ends when it returns.

    Everything imported once numba is (`watch_compiling` imports it), its ~100k objects among
    it, lives as long as the process; frozen, the garbage collector never walks it again,
    which saves ~0.2 s of interpreter teardown per run (measured by tests/bench/run.py's cold
    start), and ~0.1 s more of collections while the kernels load and the program converts
    (measured against a freeze before numba's import: the quarter circle 0.59 s of CPU
    instead of 0.68 s, the 650-curve program under paper-table1 2.32 s instead of 2.40 s).

    Stop signals are handled here, in the process's own entry point only (not in a library
    call of `main`): SIGINT, SIGTERM or SIGHUP unwinds the run, removing temporary files, and
    exits with 128 + the signal number (130, 143, 129).

    On the first run after an install the command's kernels compile in child processes
    (commands.warm_up, `run_compile_child`), whose memory ends with them.
    """
    handle_stop_signals(stop)
    WarmUp.enabled = True
    watch_compiling()  # (imports numba)
    gc.freeze()
    try:
        main()
    except Interrupted as exc:
        from nurbsfeed.files import remove_live_temporaries

        remove_live_temporaries()
        click.echo(f"nurbsfeed: stopped by {signal.Signals(exc.signum).name}", err=True)
        sys.exit(exc.exit_code)


def run_compile_child(argv: list[str]) -> None:
    """A compile child's process (nurbsfeed.jit.compile_in_children): `main` on `argv`, a
    command's warm-up, ending itself once it holds its share of compiled kernels; its exit
    status is the command's. Everything it wrote goes with it (its temporary folder, /dev/null):
    it ends without the interpreter's teardown, which would only walk numba's objects."""
    from nurbsfeed.jit import compile_child

    compile_child()
    gc.freeze()
    try:
        main(argv)
        status = 0
    except SystemExit as exc:
        status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    os._exit(status)


if __name__ == "__main__":  # pragma: no cover
    run()
