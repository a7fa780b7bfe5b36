"""What every command shares: the profile options (--machine and one override per profile key),
--method and --dialect, the --help epilog, and `reports_errors`, which turns an error into its
message on stderr and its exit code (never a traceback).
"""

from __future__ import annotations

import functools
import os
import sys
import textwrap
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import click

from nurbsfeed.choices import DIALECTS, METHOD_NAMES
from nurbsfeed.errors import EXIT_BAD_INPUT, EXIT_BROKEN_PIPE, NurbsfeedError
from nurbsfeed.machine import AXIS_KEYS, FLOAT_KEYS, INT_KEYS, JERK_MODELS, PLANNERS, load_machine

if TYPE_CHECKING:
    from nurbsfeed.machine import Machine


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


def internal_error(exc: Exception) -> str:
    """A bug's exception as one line of a summary row."""
    return " ".join(f"internal error: {type(exc).__name__}: {exc}".split())


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


def epilog(examples: str, planner: bool = True) -> str:
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

