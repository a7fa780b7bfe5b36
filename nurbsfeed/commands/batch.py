"""The files of a `convert` run: the inputs expanded (directories, globs), the outputs refused
where they would overwrite an input or each other, one file converted into a row of the
summary (`convert_one`, also the unit of work of a --jobs worker, commands.pool), and the
summary printed.
"""

from __future__ import annotations

import glob
import os
import stat
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from nurbsfeed.commands.common import internal_error
from nurbsfeed.commands.stops import check_stopped
from nurbsfeed.errors import InputError, Location, NurbsfeedError

if TYPE_CHECKING:
    from nurbsfeed.commands.progress import Progress
    from nurbsfeed.machine import Machine

GCODE_SUFFIXES = (".nc", ".ngc", ".gcode", ".tap", ".cnc", ".txt", ".json", ".mpf", ".spf",
                  ".eia")


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


def file_id(path: Path) -> tuple[int, int] | None:
    """(device, inode) of an existing regular file, links followed; None for anything else."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def same_file(a: Path, b: Path) -> bool:
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
        inputs.setdefault(file_id(source), source)
    inputs.pop(None, None)
    writers: dict[str, Path] = {}
    for source, target in zip(sources, targets):
        if target is None:
            continue
        key = os.path.realpath(target).casefold()
        if key in writers and same_file(writers[key], source):
            first = writers[key]
            aliases = "" if str(first) == str(source) else f" (as {first} and as {source})"
            raise InputError(f"this input is given twice{aliases}: give each input once (a "
                             "directory and a glob can both name it)", Location(str(source)))
        if key in writers:
            raise InputError(f"both {writers[key]} and {source} would be written here (rename "
                             "one, or convert them in separate runs)", Location(str(target)))
        writers[key] = source
        clobbered = inputs.get(file_id(target))
        if clobbered is not None:
            what = "-o" if target == named else f"the output of {source}"
            raise InputError(f"{what} would overwrite the input {clobbered}",
                             Location(str(target)))
    if trace is not None:
        clobbered = inputs.get(file_id(trace))
        if clobbered is not None:
            raise InputError(f"--trace would overwrite the input {clobbered}",
                             Location(str(trace)))
        if targets[0] is not None and same_file(trace, targets[0]):
            raise InputError("-o and --trace name the same file", Location(str(trace)))


def convert_one(source: Path, target: Path | None, machine: Machine, method: str,
                dialect: str, trace: Path | None, progress: Progress | None
                ) -> dict[str, Any]:
    """Convert one file (also the unit of work of --jobs); errors come back as data, a bug's
    exception too (one file's crash must not stop a batch)."""
    from nurbsfeed.pipeline import convert_file

    if progress:
        progress.file_started(source)

    def on_curve(result: Any) -> None:
        check_stopped()
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


def print_summary(results: list[dict[str, Any]], failures_only: bool = False) -> None:
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

