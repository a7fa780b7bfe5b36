"""`nurbsfeed convert`: NURBS programs into planned G1 moves, one file, or a batch (in parallel
with --jobs), through pipeline.convert_file (commands.batch.convert_one).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from nurbsfeed.commands.batch import (
    convert_one,
    expand_inputs,
    output_name,
    print_summary,
    refuse_overwrites,
)
from nurbsfeed.commands.common import (
    dialect_option,
    epilog,
    machine_from,
    machine_options,
    method_option,
    reports_errors,
)
from nurbsfeed.commands.pool import convert_in_pool
from nurbsfeed.commands.progress import Notice, Progress
from nurbsfeed.commands.warm_up import hand_off, profile_options, warm_up
from nurbsfeed.errors import EXIT_BAD_INPUT, InputError, Location

TAYLOR1_WARNING = ("nurbsfeed: warning: taylor1 is the paper's first-order baseline; its points "
                   "drift off the planned feed by up to a few percent, which can break the "
                   "limits (use rk2c to machine)")


@click.command(epilog=epilog(
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
    warm = warm_up("convert", [*profile_options(kwargs), "--method", method])
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
    progress = None
    if quiet:
        Notice.quiet = True
    elif sys.stderr is not None and sys.stderr.isatty():
        progress = Notice.progress = Progress(sources)
    if method == "taylor1":
        click.echo(TAYLOR1_WARNING, err=True)
    try:
        if jobs > 1 and len(sources) > 1:
            results = convert_in_pool(sources, targets, jobs, progress, warm, machine, method,
                                      dialect)
        else:
            hand_off(warm)
            results = []
            for index, (source, target) in enumerate(zip(sources, targets)):
                results.append(convert_one(source, target, machine, method, dialect, trace,
                                           progress))
                if progress:
                    progress.file_done(index, results[-1].get("points", 0))
    finally:
        if progress:
            progress.close()
            Notice.progress = None
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
        print_summary(results, failures_only=quiet)
    if failed:
        sys.exit(EXIT_BAD_INPUT)

