"""The command line: the only module that imports click, prints, and picks exit codes.

Every command is thin: parse options, call the pipeline or an analysis, print its report. Errors
from the core (NurbsfeedError) become `FILE:LINE:COL: message` on stderr with the exit code from
errors.py and no traceback. SIGINT, SIGTERM and SIGHUP become `Interrupted`, which unwinds like an
error (temporary files removed) and ends the process with 128 + the signal number.
"""

from __future__ import annotations

import functools
import gc
import glob
import importlib
import os
import signal
import stat
import sys
import textwrap
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from nurbsfeed import __version__
from nurbsfeed.choices import DIALECTS, METHOD_NAMES
from nurbsfeed.errors import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_SIGNAL_BASE,
    InputError,
    Interrupted,
    Location,
    NurbsfeedError,
    ProfileError,
)
from nurbsfeed.machine import (
    AXIS_KEYS,
    FLOAT_KEYS,
    INT_KEYS,
    JERK_MODELS,
    PLANNERS,
    load_machine,
    machine_from_mapping,
)

if TYPE_CHECKING:
    import numpy as np

    from nurbsfeed.machine import Machine
    from nurbsfeed.planning.chain import Joints
    from nurbsfeed.planning.plan import Plan
    from nurbsfeed.program import CurveBlock

TAYLOR1_WARNING = ("nurbsfeed: warning: taylor1 is the paper's first-order baseline; its points "
                   "drift off the planned feed by up to a few percent, which can break the "
                   "limits (use rk2c to machine)")
GCODE_SUFFIXES = (".nc", ".ngc", ".gcode", ".tap", ".cnc", ".txt", ".json", ".mpf", ".spf",
                  ".eia")
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def reports_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Map NurbsfeedError to its message and exit code (never a traceback); a reader of stdout
    that went away (`| head -1`) ends the run quietly with 141, as if by SIGPIPE; any other
    exception is a bug, reported on one line as `nurbsfeed: internal error: ...` with exit 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except NurbsfeedError as exc:
            click.echo(str(exc), err=True)
            sys.exit(exc.exit_code)
        except BrokenPipeError:
            _detach_stdout()
            sys.exit(EXIT_BROKEN_PIPE)
        except (click.ClickException, click.exceptions.Exit, click.Abort):
            raise  # usage errors: click prints them
        except Exception as exc:  # a bug outside a conversion (loading a profile): one line,
            click.echo(f"nurbsfeed: {internal_error(exc)}", err=True)  # as in a batch row
            sys.exit(EXIT_BAD_INPUT)

    return wrapper


def _detach_stdout() -> None:
    """Point stdout at /dev/null, so that flushing it at exit does not fail a second time."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (AttributeError, OSError, ValueError):  # no stdout, or not a real file (tests)
        pass
    finally:
        os.close(devnull)


_stopped_by = 0  # the stop signal that arrived, if one has


def _stop(signum: int, frame: Any) -> None:
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


def _check_stopped() -> None:
    if _stopped_by:
        raise Interrupted(_stopped_by)


def _unraisable(hook_args: Any) -> None:
    """Keep a stop to its one line on stderr. A finaliser the signal cut short (llvmlite's
    ObjectRef.__del__, half detached) fails again when it is collected at exit; once a stop
    signal has arrived the run only cleans up and ends, so no such report is news."""
    if not isinstance(hook_args.exc_value, Interrupted) and not _stopped_by:
        sys.__unraisablehook__(hook_args)


def _handle_stop_signals(handler: Callable[[int, Any], None]) -> None:
    sys.unraisablehook = _unraisable
    for signum in STOP_SIGNALS:
        if signal.getsignal(signum) != signal.SIG_IGN:  # nohup, a background job: stay deaf
            signal.signal(signum, handler)


def machine_options(func: Callable[..., Any] | None = None, *, planner: bool = True) -> Any:
    """--machine plus one override option per profile key (e.g. --max-feed-mm-s 50); --planner
    only where a plan is made (`planner`). The overrides are left out of --help, which names
    them once in the epilog (`_profile_help`) instead of a line each."""

    def add(func: Callable[..., Any]) -> Callable[..., Any]:
        for key in reversed(FLOAT_KEYS + INT_KEYS):
            func = click.option(f"--{key.replace('_', '-')}", key,
                                type=int if key in INT_KEYS else float, default=None,
                                hidden=True)(func)
        func = click.option("--jerk-model", "jerk_model", type=click.Choice(list(JERK_MODELS)),
                            default=None, hidden=True)(func)
        if planner:
            func = click.option("--planner", "planner", type=click.Choice(list(PLANNERS)),
                                default=None, hidden=True)(func)
        return click.option("--machine", "-m", default="default", show_default=True,
                            help="Machine profile: a built-in name (default, linuxcnc, "
                                 "paper-table1) or a YAML file. Any of its keys can be "
                                 "overridden: --KEY VALUE (below).")(func)

    return add(func) if func is not None else add


def _profile_help(planner: bool = True) -> str:
    """The epilog paragraph that names the override options."""
    keys = [f"--{key.replace('_', '-')}" for key in FLOAT_KEYS + INT_KEYS if key not in AXIS_KEYS]
    choices = f"--jerk-model {'|'.join(JERK_MODELS)}"
    if planner:
        choices += f", --planner {'|'.join(PLANNERS)}"
    text = ("Profile overrides, each one key of the profile (README, Profile keys): "
            f"{', '.join(keys)}, the per-axis --max-{{vel,acc,jerk}}-{{x,y,z}}-... limits; "
            f"{choices}.")
    # wrapped here, not by click, which would break the option names at their hyphens
    return "\b\n" + textwrap.fill(text, 78, break_on_hyphens=False, break_long_words=False)


def _epilog(examples: str, planner: bool = True) -> str:
    """A command's --help epilog: examples (kept as written), then the override options."""
    return "\b\nExamples:\n" + examples + "\n\n" + _profile_help(planner)


OVERRIDE_KEYS = FLOAT_KEYS + INT_KEYS + ("jerk_model", "planner")


def machine_from(kwargs: dict[str, Any]) -> Machine:
    overrides = {k: kwargs.pop(k, None) for k in OVERRIDE_KEYS}
    return load_machine(kwargs.pop("machine"), overrides)


method_option = click.option("--method", type=click.Choice(list(METHOD_NAMES)), default="rk2c",
                             show_default=True, help="Interpolator (docs/design.md §3).")
dialect_option = click.option("--dialect", type=click.Choice(list(DIALECTS)),
                              default="auto", show_default=True,
                              help="G-code dialect of the input.")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="nurbsfeed")
def main() -> None:
    """Plan a jerk-limited feed along NURBS toolpaths and write densified G1 moves."""


# ---- convert ---------------------------------------------------------------------------------

def expand_inputs(inputs: tuple[str, ...]) -> list[Path]:
    """Files, directories (their G-code and JSON files, sorted) and quoted globs."""
    paths: list[Path] = []
    for item in inputs:
        matches = sorted(glob.glob(item)) if glob.has_magic(item) else [item]
        if not matches:
            raise click.UsageError(f"no file matches {item!r}")
        for match in matches:
            path = Path(match)
            if path.is_dir():
                paths += sorted(p for p in path.iterdir()
                                if p.is_file() and p.suffix.lower() in GCODE_SUFFIXES)
            else:
                paths.append(path)  # a missing file fails on its own, not the batch
    if not paths:
        raise click.UsageError("no input files")
    return paths


def output_name(source: Path) -> str:
    return source.stem + ".nc" if source.suffix.lower() == ".json" else source.name


def _file_id(path: Path) -> tuple[int, int] | None:
    """(device, inode) of an existing regular file, links followed; None for anything else."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return os.path.realpath(a) == os.path.realpath(b)


def refuse_overwrites(sources: list[Path], targets: list[Path | None], named: Path | None,
                      trace: Path | None) -> None:
    """Before anything is converted: no output may be an input (by another path, a hard link or
    a symbolic link), no two inputs may write the same output (names equal up to case, for
    case-insensitive file systems), and -o and --trace must differ. `named`: the -o FILE given
    for a single input (a target of its own, not a name in a directory)."""
    inputs: dict[tuple[int, int] | None, Path] = {}
    for source in sources:
        inputs.setdefault(_file_id(source), source)
    inputs.pop(None, None)
    writers: dict[str, Path] = {}
    for source, target in zip(sources, targets):
        if target is None:
            continue
        key = os.path.realpath(target).casefold()
        if key in writers and _same_file(writers[key], source):
            first = writers[key]
            aliases = "" if str(first) == str(source) else f" (as {first} and as {source})"
            raise InputError(f"this input is given twice{aliases}: give each input once (a "
                             "directory and a glob can both name it)", Location(str(source)))
        if key in writers:
            raise InputError(f"both {writers[key]} and {source} would be written here (rename "
                             "one, or convert them in separate runs)", Location(str(target)))
        writers[key] = source
        clobbered = inputs.get(_file_id(target))
        if clobbered is not None:
            what = "-o" if target == named else f"the output of {source}"
            raise InputError(f"{what} would overwrite the input {clobbered}",
                             Location(str(target)))
    if trace is not None:
        clobbered = inputs.get(_file_id(trace))
        if clobbered is not None:
            raise InputError(f"--trace would overwrite the input {clobbered}",
                             Location(str(trace)))
        if targets[0] is not None and _same_file(trace, targets[0]):
            raise InputError("-o and --trace name the same file", Location(str(trace)))


def internal_error(exc: Exception) -> str:
    """A bug's exception as one line of a summary row."""
    return " ".join(f"internal error: {type(exc).__name__}: {exc}".split())


def _convert_one(source: Path, target: Path | None, machine: Machine, method: str,
                 dialect: str, trace: Path | None, progress: _Progress | None
                 ) -> dict[str, Any]:
    """Convert one file (also the unit of work of --jobs); errors come back as data, a bug's
    exception too (one file's crash must not stop a batch)."""
    from nurbsfeed.pipeline import convert_file

    if progress:
        progress.file_started(source)

    def on_curve(result: Any) -> None:
        _check_stopped()
        if progress:
            progress.curve_done(result)

    start = time.perf_counter()
    try:
        report = convert_file(source, target, machine, method, dialect, trace,
                              stdout=sys.stdout.buffer if target is None else None,
                              on_curve=on_curve)
    except NurbsfeedError as exc:
        return {"source": str(source), "error": str(exc)}
    except BrokenPipeError:
        raise  # from stdout only (convert_file): the run ends quietly
    except Exception as exc:  # a bug: reported in the file's row, and the batch goes on
        return {"source": str(source), "error": internal_error(exc), "internal": True}
    return {"source": str(source), "target": str(target) if target else "-",
            "curves": len(report.curves), "points": report.n_points,
            "cycle_s": report.cycle_time_s, "wall_s": time.perf_counter() - start}


# ---- on a terminal: the status line, and the notice of a first compile ----

PROGRESS_TICK_S = 0.5  # under --jobs, the status line's clock moves on this often
COMPILE_NOTICE_AFTER_S = 1.0  # compiling longer than this says so (once a run)


class _Notice:
    """Whether the compile notice may show (not under -q), and, in a --jobs worker, the flag
    the workers share so that it shows once for all of them."""

    quiet = False
    watching = False
    shared: Any = None


_progress: _Progress | None = None  # the status line of the batch being converted, if any


def _say_compiling() -> None:
    if _Notice.quiet:
        return
    if _Notice.shared is not None:
        with _Notice.shared.get_lock():
            if _Notice.shared.value:
                return
            _Notice.shared.value = 1
    from nurbsfeed.jit import FIRST_COMPILE_S

    text = f"nurbsfeed: compiling nurbsfeed's kernels once after install, ~{FIRST_COMPILE_S:.0f} s"
    if _progress:
        _progress.message(text)
    else:
        sys.stderr.write(text + "\n")
        sys.stderr.flush()


def _watch_compiling() -> None:
    if not _Notice.watching:
        _Notice.watching = True
        from nurbsfeed.jit import watch_compiling

        watch_compiling(COMPILE_NOTICE_AFTER_S, _say_compiling)


def _compile_notice_shared() -> Any:
    """The flag --jobs workers share to show the compile notice once (None: do not show it)."""
    if _Notice.quiet:
        return None
    import multiprocessing

    return multiprocessing.Value("b", 0)


# ---- --jobs: worker processes ----

_worker_busy = False  # in a --jobs worker: a file is being converted
WORKER_STOP_S = 10.0  # how long a stopped worker has to remove its temporary files


def _worker_stop(signum: int, frame: Any) -> None:
    """A worker's signal handler: unwind the file being converted (its temporary files go);
    idle, just end."""
    if not _worker_busy:
        os._exit(EXIT_SIGNAL_BASE + signum)
    _stop(signum, frame)


def _init_worker(notice_shown: Any) -> None:
    _handle_stop_signals(_worker_stop)
    _Notice.quiet, _Notice.shared = notice_shown is None, notice_shown
    _watch_compiling()


def _convert_in_worker(*args: Any) -> dict[str, Any]:
    global _worker_busy
    _worker_busy = True
    try:
        return _convert_one(*args)
    except Interrupted as exc:
        os._exit(exc.exit_code)  # cleaned up; the parent, signalled too, reports the stop
    finally:
        _worker_busy = False


def convert_in_pool(sources: list[Path], targets: list[Path | None], jobs: int,
                    progress: _Progress | None, *args: Any) -> list[dict[str, Any]]:
    """Convert in `jobs` worker processes; `args`: machine, method, dialect.

    A worker that dies (killed, out of memory, a crash in compiled code) breaks the pool and
    fails the files in flight, at most `jobs` of them, since files are handed out one at a time;
    each of those is converted again in a process of its own, so that only a file that kills
    its worker fails, and the rest go on in a new pool.
    """
    results: dict[int, dict[str, Any]] = {}
    todo = list(range(len(sources)))
    while todo:
        lost, todo = _pool_round(todo, jobs, sources, targets, args, results, progress)
        for index in lost:
            if _pool_round([index], 1, sources, targets, args, results, progress)[0]:
                results[index] = {"source": str(sources[index]), "error": (
                    "internal error: BrokenProcessPool: the worker process converting this "
                    "file died (killed by a signal, or out of memory)")}
    return [results[index] for index in range(len(sources))]


def _pool_round(todo: list[int], jobs: int, sources: list[Path], targets: list[Path | None],
                args: tuple[Any, ...], results: dict[int, dict[str, Any]],
                progress: _Progress | None) -> tuple[list[int], list[int]]:
    """Convert files `todo` into `results` until done or the pool breaks: (files in flight when
    it broke, files not handed out). The status line moves on as files finish, and its clock
    every PROGRESS_TICK_S in between."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    waiting = todo[::-1]
    lost: list[int] = []
    with ProcessPoolExecutor(max_workers=min(jobs, len(todo)), initializer=_init_worker,
                             initargs=(_compile_notice_shared(),)) as pool:
        try:
            running: dict[Any, int] = {}
            while (waiting or running) and not lost:
                while waiting and len(running) < jobs:
                    index = waiting.pop()
                    running[pool.submit(_convert_in_worker, sources[index], targets[index],
                                        *args, None, False)] = index
                done, _ = wait(running, timeout=PROGRESS_TICK_S if progress else None,
                               return_when=FIRST_COMPLETED)
                for future in done:
                    index = running.pop(future)
                    try:
                        results[index] = future.result()
                    except BrokenProcessPool:
                        lost.append(index)
                    else:
                        if progress:
                            progress.file_done(index, results[index].get("points", 0))
                if progress and not done:
                    progress.show()
            lost += running.values()
        except Interrupted as exc:
            pool.shutdown(wait=False, cancel_futures=True)
            for child in multiprocessing.active_children():
                if child.pid is not None:  # (started: active children always are)
                    os.kill(child.pid, exc.signum)  # each removes its temporary files and ends
            for child in multiprocessing.active_children():
                child.join(WORKER_STOP_S)
                if child.is_alive():  # stuck in compiled code past the grace period
                    child.kill()
            # The pool's manager thread closes its wake-up pipe as it notices the workers gone;
            # concurrent.futures' exit hook writes to that pipe unlocked (Python < 3.12), so
            # the thread is joined here rather than raced at interpreter exit.
            pool.shutdown(wait=True)
            raise
    return lost, waiting[::-1]


class _Progress:
    """One status line on stderr, rewritten in place (only when stderr is a terminal): files
    done of total, points written, elapsed time and time left.

    The fraction done counts input bytes: those of the files finished, plus, for the file being
    converted in this process, its share up to the source line of the last converted curve
    (cheap, monotone, and right for programs whose curves are spread through the file). Time
    left is the elapsed time scaled by the fraction still to do.
    """

    def __init__(self, sources: list[Path]) -> None:
        self.sizes = [_size(source) for source in sources]
        self.total = max(1, sum(self.sizes))
        self.files, self.files_done, self.bytes_done, self.points = len(sources), 0, 0, 0
        self.current, self.current_points = 0.0, 0  # the file being converted here
        self.lines = 1
        self.start = time.monotonic()
        self.last = -1.0
        self.lock = threading.Lock()  # the compile notice comes from a timer thread

    def file_started(self, source: Path) -> None:
        self.current, self.current_points = 0.0, 0
        self.lines = _line_count(source)

    def curve_done(self, result: Any) -> None:
        self.current = min(1.0, (result.location.line or 1) / self.lines)
        self.current_points += result.n_points
        self.show()

    def file_done(self, index: int, points: int) -> None:
        self.files_done += 1
        self.bytes_done += self.sizes[index]
        self.points += points
        self.current, self.current_points = 0.0, 0
        self.show(force=True)

    def show(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self.last < 0.1:
            return
        self.last = now
        elapsed_s = now - self.start
        done = min(1.0, (self.bytes_done + self.current * self.sizes[
            min(self.files_done, self.files - 1)]) / self.total)
        left = (f"~{_duration(elapsed_s * (1.0 - done) / done)} left" if done > 0.0
                else "time left unknown")
        self._write(f"\r{self.files_done} of {self.files} files, "
                    f"{self.points + self.current_points:,} points, "
                    f"{_duration(elapsed_s)} elapsed, {left}\033[K")

    def message(self, text: str) -> None:
        """A line of its own above the status line."""
        self._write(f"\r\033[K{text}\n")
        self.last = -1.0

    def close(self) -> None:
        self._write("\r\033[K")

    def _write(self, text: str) -> None:
        with self.lock:
            sys.stderr.write(text)
            sys.stderr.flush()


def _size(path: Path) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0


def _line_count(path: Path) -> int:
    try:
        with open(path, "rb") as handle:
            return max(1, sum(chunk.count(b"\n") for chunk in
                              iter(lambda: handle.read(1 << 20), b"")))
    except OSError:
        return 1


def _duration(seconds: float) -> str:
    """12 s, 3 min 05 s, 1 h 02 min."""
    whole = int(round(seconds))
    if whole < 60:
        return f"{whole} s"
    if whole < 3600:
        return f"{whole // 60} min {whole % 60:02d} s"
    return f"{whole // 3600} h {whole % 3600 // 60:02d} min"


@main.command(epilog=_epilog(
    "  nurbsfeed convert part.nc -o part-g1.nc            # one program (stdout without -o)\n"
    "  nurbsfeed convert shop/ more/*.nc -o out/ --jobs 2 # a batch\n"
    "  nurbsfeed convert curve.json -m linuxcnc --max-feed-mm-s 150 -o curve.ngc"))
@click.argument("inputs", nargs=-1, required=True)
@click.option("-o", "--output", type=click.Path(path_type=Path),
              help="Output file, or a directory for several inputs (names kept; .json -> .nc). "
                   "Default: stdout for a single input.")
@machine_options
@method_option
@dialect_option
@click.option("--trace", type=click.Path(path_type=Path), help="Write the trace CSV here "
              "(single input only).")
@click.option("--jobs", "-j", type=click.IntRange(1, 64), default=1, show_default=True,
              help="Convert files in this many parallel processes.")
@click.option("--quiet", "-q", is_flag=True,
              help="No summary or progress on stderr; only the files that failed, if any.")
@reports_errors
def convert(inputs: tuple[str, ...], output: Path | None, method: str, dialect: str,
            trace: Path | None, jobs: int, quiet: bool, **kwargs: Any) -> None:
    """Convert NURBS programs (G-code or JSON curves) into planned G1 moves."""
    machine = machine_from(kwargs)
    sources = expand_inputs(inputs)
    many = len(sources) > 1 or (output is not None and output.is_dir())
    if many and output is None:
        raise click.UsageError("several inputs need -o DIR")
    if many and output is not None and output.exists() and not output.is_dir():
        raise click.UsageError(f"-o {output}: several inputs need a directory")
    if trace is not None and len(sources) > 1:
        raise click.UsageError("--trace takes a single input")
    targets = [output / output_name(s) if many and output else output for s in sources]
    refuse_overwrites(sources, targets, None if many else output, trace)
    if output is None and sys.stdout is None:
        raise InputError("cannot write output (standard output is closed)", Location("-"))
    if many and output is not None:
        try:
            output.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create the output directory ({exc.strerror})",
                             Location(str(output))) from None
    global _progress
    if quiet:
        _Notice.quiet = True
    elif sys.stderr is not None and sys.stderr.isatty():
        _progress = _Progress(sources)
    if method == "taylor1":
        click.echo(TAYLOR1_WARNING, err=True)
    try:
        if jobs > 1 and len(sources) > 1:
            results = convert_in_pool(sources, targets, jobs, _progress, machine, method,
                                      dialect)
        else:
            results = []
            for index, (source, target) in enumerate(zip(sources, targets)):
                results.append(_convert_one(source, target, machine, method, dialect, trace,
                                            _progress))
                if _progress:
                    _progress.file_done(index, results[-1].get("points", 0))
    finally:
        if _progress:
            _progress.close()
            _progress = None
    failed = [r for r in results if "error" in r]
    if not many:
        if failed:
            error = failed[0]
            click.echo(f"{error['source']}: {error['error']}" if error.get("internal")
                       else error["error"], err=True)
            sys.exit(EXIT_BAD_INPUT)
        if output is not None and not quiet:
            r = results[0]
            curves = "1 curve" if r["curves"] == 1 else f"{r['curves']} curves"
            click.echo(f"{r['source']}: {curves}, {r['points']:,} points, "
                       f"cycle {r['cycle_s']:.3f} s -> {r['target']}", err=True)
        return
    if not quiet or failed:
        _print_summary(results, failures_only=quiet)
    if failed:
        sys.exit(EXIT_BAD_INPUT)


def _print_summary(results: list[dict[str, Any]], failures_only: bool = False) -> None:
    """The per-file table and the count; with failures_only (-q), the failed files' rows."""
    if failures_only:
        for r in results:
            if "error" in r:  # located errors name their file already
                click.echo(r["error"] if r["error"].startswith(r["source"])
                           else f"{r['source']}: {r['error']}", err=True)
    else:
        _print_table(results)
    ok = sum("error" not in r for r in results)
    click.echo(f"{ok} of {len(results)} files converted", err=True)


def _print_table(results: list[dict[str, Any]]) -> None:
    width = max(len(r["source"]) for r in results)
    click.echo(f"{'file':<{width}}  {'curves':>6}  {'points':>10}  {'cycle s':>9}  status",
               err=True)
    for r in results:
        if "error" in r:
            click.echo(f"{r['source']:<{width}}  {'-':>6}  {'-':>10}  {'-':>9}  FAILED: "
                       f"{r['error']}", err=True)
        else:
            click.echo(f"{r['source']:<{width}}  {r['curves']:>6}  {r['points']:>10,}  "
                       f"{r['cycle_s']:>9.3f}  ok -> {r['target']}", err=True)


# ---- plan ------------------------------------------------------------------------------------

@main.command(epilog=_epilog(
    "  nurbsfeed plan samples/butterfly.json -m paper-table1"))
@click.argument("input", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("--reference", is_flag=True,
              help="Also find a jerk-limited schedule under the same limits, by its own code "
                   "(sequential linear programming), and compare (seconds to minutes a curve).")
@machine_options
@dialect_option
@reports_errors
def plan(input: Path, dialect: str, reference: bool, **kwargs: Any) -> None:
    """Key points, nominal and scanned speeds, segments and cycle time of every curve; a chain
    of curves that join (planned as one) lists its joints: turn, curvature jump and speed."""
    from nurbsfeed.analysis import time_optimal_bound_s
    from nurbsfeed.chains import ChainWindow, chain_items
    from nurbsfeed.pipeline import chain_block, joint_speeds, plan_block
    from nurbsfeed.planning.plan import KIND_NAMES
    from nurbsfeed.readers import read_program

    if reference:
        try:
            importlib.import_module("nurbsfeed.analysis.bound")  # scipy, an extra
        except ImportError:
            click.echo(REFERENCE_NEEDS_SCIPY, err=True)
            sys.exit(EXIT_BAD_INPUT)
    machine = machine_from(kwargs)
    index = 0
    for window in chain_items(read_program(input, dialect), machine):
        if not isinstance(window, ChainWindow):
            continue
        item, chain, found = chain_block(window, machine.limits)
        p = plan_block(item, machine)
        lim = p.limits
        unit = "mm"  # an inch program's too: every report is in the profile's unit
        n_curves = len(window.blocks)
        if n_curves == 1:
            click.echo(f"curve {index} {item.curve.name} ({item.location})")
        else:
            click.echo(f"curves {index}-{index + n_curves - 1}, a chain planned as one curve "
                       f"({item.location}; u below is the chain's, 0 to 1)")
        click.echo(f"  degree {item.curve.degree}, {item.curve.n_ctrl} control points, "
                   f"length {p.length_mm:.6f} {unit}")
        keys = (f"{len(p.key_node)} rests (the {p.planner} planner's keys)" if p.planner != "scurve"
                else f"{len(p.key_node)} key points after {p.fix_rounds} limit-fix rounds")
        click.echo(f"  kappa0 {p.kappa0_1_mm:.6g} 1/{unit}; {p.n_peaks_above_threshold} "
                   f"curvature peaks >= kappa0; {keys}")
        click.echo(f"  {'#':>3} {'kind':<6} {'u':>12} {'s':>12} {'kappa':>12} "
                   f"{'nominal':>10} {'scanned':>10}")
        for k, node in enumerate(p.key_node):
            click.echo(f"  {k:>3} {KIND_NAMES[int(p.key_kind[k])]:<6} "
                       f"{item.curve.input_u(p.grid.u[node]):>12.8f} "
                       f"{p.grid.s_mm[node]:>12.6f} {p.grid.kappa_1_mm[node]:>12.6g} "
                       f"{p.key_nominal_mm_s[k]:>10.4f} {p.key_v_mm_s[k]:>10.4f}")
        if p.planner != "scurve":
            _echo_stretches(p, unit)
        else:
            _echo_segments(p, unit)
        if n_curves > 1:
            _echo_joints(index, found, joint_speeds(p, chain), unit)
        bound = time_optimal_bound_s(p, item)
        click.echo(f"  cycle time {p.cycle_time_s:.3f} s ({p.n_periods} periods of "
                   f"{lim.period_s * 1e3:g} ms; time scale {p.time_scale:.9f})")
        click.echo(f"  time-optimal bound {bound:.3f} s (acceleration-limited, no jerk limit): "
                   f"planned is {100 * (p.cycle_time_s / bound - 1):+.1f}%" if bound > 0 else
                   "  time-optimal bound 0 s (zero length)")
        if reference and bound > 0:
            click.echo(_reference_line(item, machine, p.cycle_time_s, bound))
        index += n_curves
    if index == 0:
        click.echo("no NURBS curves in the input")


def _echo_joints(first: int, found: Joints, speed_mm_s: np.ndarray, unit: str) -> None:
    """A chain's joints (design §3b): where, how far the tangent turns, the jump of the
    curvature vector, the cap the period rule sets (a corner rests: 0) and the speed the
    stepped points cross at."""
    import numpy as np

    click.echo(f"  joints ({unit}, {unit}/s; speed from the stepped points across the joint):")
    click.echo(f"  {'#':>3} {'curves':>11} {'u':>12} {'turn_deg':>10} {'dkappa':>12} "
               f"{'cap':>10} {'speed':>10}")
    for j in range(found.u.size):
        curves = f"{first + j}|{first + j + 1}"
        cap = "-" if np.isinf(found.cap_mm_s[j]) else f"{found.cap_mm_s[j]:.4f}"
        click.echo(f"  {j:>3} {curves:>11} {found.u[j]:>12.8f} "
                   f"{np.degrees(found.turn_rad[j]):>10.6f} {found.kappa_jump_1_mm[j]:>12.6g} "
                   f"{cap:>10} {speed_mm_s[j]:>10.4f}")


def _echo_segments(p: Plan, unit: str) -> None:
    """The S-curve plan's segments between key points."""
    from nurbsfeed.planning.scurve import transition_distance_mm

    a, j = p.scurve_acc_mm_s2, p.scurve_jerk_mm_s3
    click.echo(f"  segments ({unit}, {unit}/s):")
    click.echo(f"  {'#':>3} {'length':>12} {'v_start':>10} {'v_peak':>10} {'v_end':>10} "
               f"{'hold_in':>9} {'hold_out':>9} {'cruise':>10}")
    key_s = p.key_s_mm
    for i in range(len(p.key_node) - 1):
        length = key_s[i + 1] - key_s[i]
        vs, ve, vp = p.key_v_mm_s[i], p.key_v_mm_s[i + 1], p.seg_peak_mm_s[i]
        cruise = (length - p.seg_hold_start_mm[i] - p.seg_hold_end_mm[i]
                  - transition_distance_mm(vs, vp, a, j) - transition_distance_mm(vp, ve, a, j))
        click.echo(f"  {i:>3} {length:>12.6f} {vs:>10.4f} {vp:>10.4f} {ve:>10.4f} "
                   f"{p.seg_hold_start_mm[i]:>9.4f} {p.seg_hold_end_mm[i]:>9.4f} "
                   f"{max(cruise, 0.0):>10.4f}")


def _echo_stretches(p: Plan, unit: str) -> None:
    """The stretches between rests of a plan whose keys are the rests alone (the envelope and
    optimal planners')."""
    click.echo(f"  {p.planner} schedule: {p.fix_rounds} limit-fix rounds, uniform slowdown "
               f"{p.uniform_slowdown:.4f}; stretches between rests ({unit}, {unit}/s):")
    click.echo(f"  {'#':>3} {'length':>12} {'v_peak':>10} {'periods':>10}")
    key_s = p.key_s_mm
    for i in range(len(p.key_node) - 1):
        click.echo(f"  {i:>3} {key_s[i + 1] - key_s[i]:>12.6f} {p.seg_peak_mm_s[i]:>10.4f} "
                   f"{int(p.piece_periods[i]):>10}")


def _reference_line(block: CurveBlock, machine: Machine, cycle_s: float, bound_s: float
                    ) -> str:
    """`plan --reference`: the jerk-limited reference schedule's cycle and the plan's ratio."""
    from nurbsfeed.analysis.bound import jerk_limited_schedule

    try:
        ref = jerk_limited_schedule(block.curve, machine.limits, block.feed_u, block.feed_mm_s)
    except (RuntimeError, ValueError) as exc:  # an LP HiGHS could not solve, NaN geometry
        return f"  jerk-limited reference: not found ({exc})"
    return (f"  jerk-limited reference {ref.cycle_s:.3f} s (keeps every limit; the optimum lies "
            f"between {bound_s:.3f} and {ref.cycle_s:.3f} s): planned is "
            f"{100 * (cycle_s / ref.cycle_s - 1):+.1f}%")


# ---- compare, check, plot --------------------------------------------------------------------

PLOT_NEEDS_MATPLOTLIB = "nurbsfeed plot needs matplotlib: pip install 'nurbsfeed[plot]'"
REFERENCE_NEEDS_SCIPY = ("nurbsfeed plan --reference needs scipy: "
                         "pip install 'nurbsfeed[reference]'")


@main.command(epilog=_epilog(
    "  nurbsfeed compare samples/butterfly.json -m paper-table1 --json"))
@click.argument("input", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@machine_options
@dialect_option
@click.option("--repeat", type=click.IntRange(1, 100_000), default=25, show_default=True,
              help="Timed kernel runs per method and curve after the compile; the median counts.")
@click.option("--json", "as_json", is_flag=True, help="Print the table as JSON.")
@reports_errors
def compare(input: Path, dialect: str, repeat: int, as_json: bool, **kwargs: Any) -> None:
    """The paper's Table 2 on any input: feed fluctuation and time per step of each method."""
    import json

    from nurbsfeed.analysis import compare_file, render_comparison

    name = kwargs["machine"]
    result = compare_file(input, machine_from(kwargs), dialect, repeat)
    click.echo(json.dumps(dict(result.as_dict(), machine=name), indent=2) if as_json
               else render_comparison(result, name))


@main.command(epilog=_epilog(
    "  nurbsfeed check samples/butterfly.json butterfly.nc   # under its recorded profile\n"
    "  nurbsfeed check part.nc part-g1.nc --json", planner=False))
@click.argument("source", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("output", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@machine_options(planner=False)
@dialect_option
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@reports_errors
def check(source: Path, output: Path, dialect: str, as_json: bool, **kwargs: Any) -> None:
    """Verify a converted program against its source: exit 1 when a limit is broken."""
    import json

    from nurbsfeed.analysis import check_files, render_check
    from nurbsfeed.errors import EXIT_OK, EXIT_VIOLATION

    machine = _machine_of(output, kwargs)
    report = check_files(source, output, machine, dialect)
    click.echo(json.dumps(dict(report.as_dict(), machine=machine.name), indent=2) if as_json
               else render_check(report, machine.name))
    sys.exit(EXIT_OK if report.ok else EXIT_VIOLATION)


def _machine_of(output: Path, kwargs: dict[str, Any]) -> Machine:
    """The profile to check `output` under: the one recorded in it (gcode.profile_record),
    with the overrides, if any; or -m's, with them. Either must agree with the record on every
    key (a program checked under limits it was not made for fails for no fault of its own). An
    output without a record (no curves, or an older nurbsfeed's) is checked under -m, the
    default profile if none is given."""
    from nurbsfeed.files import InputFile
    from nurbsfeed.gcode.profile_record import differences, read_record

    recorded = read_record(InputFile(output).lines(), str(output))
    named = (click.get_current_context().get_parameter_source("machine")
             is not click.core.ParameterSource.DEFAULT)
    if recorded is None or named:
        machine = machine_from(kwargs)
    else:  # the overrides, if any, apply to the recorded profile
        overrides = {key: kwargs[key] for key in OVERRIDE_KEYS if kwargs.get(key) is not None}
        if not overrides:
            return recorded.machine
        machine = machine_from_mapping(dict(recorded.machine.profile), recorded.name,
                                       overrides=overrides, name=recorded.name)
    if recorded is not None:
        changed = differences(recorded.machine, machine)
        if changed:
            raise ProfileError(
                f"converted under the profile {recorded.name} (recorded here), but checked "
                f"under {machine.name}, which differs: {'; '.join(changed)} (leave out -m and "
                "the overrides to check under the recorded profile)", recorded.location)
    return machine


@main.command(epilog=_epilog(
    "  nurbsfeed plot samples/butterfly.json -m paper-table1 -o butterfly.png"))
@click.argument("input", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="The PNG to write.")
@click.option("--curve", "curve_index", type=click.IntRange(0), default=0, show_default=True,
              help="Which curve of the input (from 0, in file order).")
@machine_options
@method_option
@dialect_option
@reports_errors
def plot(input: Path, output: Path, curve_index: int, method: str, dialect: str,
         **kwargs: Any) -> None:
    """The paper's figures for one curve: path, feed, accelerations, jerks, chord error, FF."""
    try:
        from nurbsfeed import plotting
    except ImportError:
        click.echo(PLOT_NEEDS_MATPLOTLIB, err=True)
        sys.exit(EXIT_BAD_INPUT)
    from nurbsfeed.analysis import curve_run, run_series
    from nurbsfeed.files import output_target

    if _file_id(output) is not None and _same_file(input, output):
        raise InputError(f"-o would overwrite the input {input}", Location(str(output)))
    output_target(output)  # refused now, not after the run
    name = kwargs["machine"]
    block, plan, result = curve_run(input, machine_from(kwargs), method, dialect, curve_index)
    try:
        plotting.plot_run(output, plan, result, run_series(block, plan, result), name)
    except OSError as exc:
        raise InputError(f"cannot write output ({exc.strerror or exc})",
                         Location(str(output))) from None


def run() -> None:
    """The console script: `main` in a process that ends when it returns.

    Everything imported by now, numba's ~100k objects among it, lives as long as the process;
    frozen, the garbage collector never walks it again, which saves ~0.2 s of interpreter
    teardown per run (measured by tests/bench/run.py's cold start).

    Stop signals are handled here, in the process's own entry point only (not in a library
    call of `main`): SIGINT, SIGTERM or SIGHUP unwinds the run, removing temporary files, and
    exits with 128 + the signal number (130, 143, 129).
    """
    gc.freeze()
    _handle_stop_signals(_stop)
    _watch_compiling()
    try:
        main()
    except Interrupted as exc:
        from nurbsfeed.files import remove_live_temporaries

        remove_live_temporaries()
        click.echo(f"nurbsfeed: stopped by {signal.Signals(exc.signum).name}", err=True)
        sys.exit(exc.exit_code)


if __name__ == "__main__":  # pragma: no cover
    run()
