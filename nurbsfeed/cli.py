"""The command line: the only module that imports click, prints, and picks exit codes.

Every command is thin: parse options, call the pipeline or an analysis, print its report. Errors
from the core (NurbsfeedError) become `FILE:LINE:COL: message` on stderr with the exit code from
errors.py and no traceback.
"""

from __future__ import annotations

import functools
import gc
import glob
import sys
import time
from pathlib import Path
from typing import Any, Callable

import click

from nurbsfeed import __version__
from nurbsfeed.errors import EXIT_BAD_INPUT, NurbsfeedError
from nurbsfeed.interpolate import METHODS
from nurbsfeed.machine import FLOAT_KEYS, INT_KEYS, Machine, load_machine

TAYLOR1_WARNING = ("nurbsfeed: warning: taylor1 is the paper's first-order baseline; its points "
                   "drift off the planned feed by up to a few percent, which can break the "
                   "limits (use rk2c to machine)")
GCODE_SUFFIXES = (".nc", ".ngc", ".gcode", ".tap", ".cnc", ".txt", ".json", ".mpf", ".eia")


def reports_errors(func: Callable[..., Any]) -> Callable[..., Any]:
    """Map NurbsfeedError to its message and exit code (never a traceback)."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except NurbsfeedError as exc:
            click.echo(str(exc), err=True)
            sys.exit(exc.exit_code)

    return wrapper


def machine_options(func: Callable[..., Any]) -> Callable[..., Any]:
    """--machine plus one override option per profile key (e.g. --max-feed-mm-s 50)."""
    for key in reversed(FLOAT_KEYS + INT_KEYS):
        func = click.option(f"--{key.replace('_', '-')}", key,
                            type=int if key in INT_KEYS else float, default=None,
                            help=f"Override the profile's {key}.")(func)
    return click.option("--machine", "-m", default="default", show_default=True,
                        help="Machine profile: a built-in name (default, paper-table1) or a "
                             "YAML file.")(func)


def machine_from(kwargs: dict[str, Any]) -> Machine:
    overrides = {k: kwargs.pop(k) for k in FLOAT_KEYS + INT_KEYS}
    return load_machine(kwargs.pop("machine"), overrides)


method_option = click.option("--method", type=click.Choice(list(METHODS)), default="rk2c",
                             show_default=True, help="Interpolator (SPEC §3).")
dialect_option = click.option("--dialect", type=click.Choice(["auto", "fanuc", "linuxcnc"]),
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
            raise click.UsageError(f"no file matches '{item}'")
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


def _convert_one(source: Path, target: Path | None, machine: Machine, method: str,
                 dialect: str, trace: Path | None, progress: bool) -> dict[str, Any]:
    """Convert one file (also the unit of work of --jobs); errors come back as data."""
    from nurbsfeed.pipeline import convert_file

    status = _Progress(source) if progress else None
    start = time.perf_counter()
    try:
        report = convert_file(source, target, machine, method, dialect, trace,
                              stdout=sys.stdout.buffer if target is None else None,
                              on_curve=status.update if status else None)
    except NurbsfeedError as exc:
        if status:
            status.close()
        return {"source": str(source), "error": str(exc)}
    if status:
        status.close()
    return {"source": str(source), "target": str(target) if target else "-",
            "curves": len(report.curves), "points": report.n_points,
            "cycle_s": report.cycle_time_s, "wall_s": time.perf_counter() - start}


class _Progress:
    """A progress bar on stderr (only used when stderr is a terminal).

    The fraction done is the source line of the last converted curve over the file's line
    count: cheap, monotone, and right for programs whose curves are spread through the file.
    """

    WIDTH = 30

    def __init__(self, source: Path) -> None:
        self.name, self.curves, self.points, self.last = source.name, 0, 0, 0.0
        self.start = time.monotonic()
        try:
            with open(source, "rb") as handle:
                self.lines = max(1, sum(chunk.count(b"\n") for chunk in
                                        iter(lambda: handle.read(1 << 20), b"")))
        except OSError:
            self.lines = 1

    def update(self, result: Any) -> None:
        self.curves += 1
        self.points += result.n_points
        now = time.monotonic()
        if now - self.last < 0.1:
            return
        self.last = now
        done = min(1.0, (result.location.line or 1) / self.lines)
        filled = int(done * self.WIDTH)
        eta = (now - self.start) * (1.0 - done) / done if done > 0 else 0.0
        sys.stderr.write(f"\r{self.name} [{'#' * filled}{'.' * (self.WIDTH - filled)}] "
                         f"{100 * done:3.0f}%  {self.curves} curves, {self.points:,} points, "
                         f"{eta:.0f} s left ")
        sys.stderr.flush()

    def close(self) -> None:
        sys.stderr.write("\r\033[K")
        sys.stderr.flush()


@main.command()
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
@click.option("--quiet", "-q", is_flag=True, help="No summary on stderr.")
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
    if many and output is not None:
        output.mkdir(parents=True, exist_ok=True)
    targets = [output / output_name(s) if many and output else output for s in sources]
    progress = sys.stderr.isatty() and not quiet
    if method == "taylor1":
        click.echo(TAYLOR1_WARNING, err=True)
    if jobs > 1 and len(sources) > 1:
        from concurrent.futures import ProcessPoolExecutor  # 20 ms: only for --jobs

        with ProcessPoolExecutor(max_workers=jobs) as pool:
            results = list(pool.map(_convert_one, sources, targets,
                                    [machine] * len(sources), [method] * len(sources),
                                    [dialect] * len(sources), [None] * len(sources),
                                    [False] * len(sources)))
    else:
        results = [_convert_one(s, t, machine, method, dialect, trace, progress)
                   for s, t in zip(sources, targets)]
    failed = [r for r in results if "error" in r]
    if not many:
        if failed:
            click.echo(failed[0]["error"], err=True)
            sys.exit(EXIT_BAD_INPUT)
        if output is not None and not quiet:
            r = results[0]
            click.echo(f"{r['source']}: {r['curves']} curves, {r['points']:,} points, "
                       f"cycle {r['cycle_s']:.3f} s -> {r['target']}", err=True)
        return
    if not quiet or failed:
        _print_summary(results)
    if failed:
        sys.exit(EXIT_BAD_INPUT)


def _print_summary(results: list[dict[str, Any]]) -> None:
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
    ok = sum("error" not in r for r in results)
    click.echo(f"{ok} of {len(results)} files converted", err=True)


# ---- plan ------------------------------------------------------------------------------------

@main.command()
@click.argument("input", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@machine_options
@dialect_option
@reports_errors
def plan(input: Path, dialect: str, **kwargs: Any) -> None:
    """Key points, nominal and scanned speeds, segments and cycle time of every curve."""
    from nurbsfeed.analysis import time_optimal_bound_s
    from nurbsfeed.pipeline import plan_block, read_program, read_text
    from nurbsfeed.planning.planner import KIND_NAMES
    from nurbsfeed.planning.scurve import transition_distance_mm
    from nurbsfeed.program import CurveBlock

    machine = machine_from(kwargs)
    text = read_text(input)
    index = 0
    for item in read_program(input, text, dialect, machine.decimals):
        if not isinstance(item, CurveBlock):
            continue
        p = plan_block(item, machine)
        lim = p.limits
        unit = item.units
        click.echo(f"curve {index} {item.curve.name} ({item.location})")
        click.echo(f"  degree {item.curve.degree}, {item.curve.n_ctrl} control points, "
                   f"length {p.length_mm:.6f} {unit}")
        click.echo(f"  kappa0 {p.kappa0_1_mm:.6g} 1/{unit}; {p.n_peaks_above_threshold} "
                   f"curvature peaks >= kappa0; {len(p.key_node)} key points after "
                   f"{p.fix_rounds} limit-fix rounds")
        click.echo(f"  {'#':>3} {'kind':<6} {'u':>12} {'s':>12} {'kappa':>12} "
                   f"{'nominal':>10} {'scanned':>10}")
        for k, node in enumerate(p.key_node):
            click.echo(f"  {k:>3} {KIND_NAMES[int(p.key_kind[k])]:<6} "
                       f"{item.curve.input_u(p.grid.u[node]):>12.8f} "
                       f"{p.grid.s_mm[node]:>12.6f} {p.grid.kappa_1_mm[node]:>12.6g} "
                       f"{p.key_nominal_mm_s[k]:>10.4f} {p.key_v_mm_s[k]:>10.4f}")
        a, j = lim.acc_mm_s2, lim.jerk_mm_s3
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
        bound = time_optimal_bound_s(p)
        click.echo(f"  cycle time {p.cycle_time_s:.3f} s ({p.n_periods} periods of "
                   f"{lim.period_s * 1e3:g} ms; time scale {p.time_scale:.9f})")
        click.echo(f"  time-optimal bound {bound:.3f} s (acceleration-limited, no jerk limit): "
                   f"planned is {100 * (p.cycle_time_s / bound - 1):+.1f}%" if bound > 0 else
                   "  time-optimal bound 0 s (zero length)")
        index += 1
    if index == 0:
        click.echo("no NURBS curves in the input")



# ---- compare, check, plot --------------------------------------------------------------------

PLOT_NEEDS_MATPLOTLIB = "nurbsfeed plot needs matplotlib: pip install 'nurbsfeed[plot]'"


@main.command()
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


@main.command()
@click.argument("source", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.argument("output", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@machine_options
@dialect_option
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON.")
@reports_errors
def check(source: Path, output: Path, dialect: str, as_json: bool, **kwargs: Any) -> None:
    """Verify a converted program against its source: exit 1 when a limit is broken."""
    import json

    from nurbsfeed.analysis import check_files, render_check
    from nurbsfeed.errors import EXIT_OK, EXIT_VIOLATION

    name = kwargs["machine"]
    report = check_files(source, output, machine_from(kwargs), dialect)
    click.echo(json.dumps(dict(report.as_dict(), machine=name), indent=2) if as_json
               else render_check(report, name))
    sys.exit(EXIT_OK if report.ok else EXIT_VIOLATION)


@main.command()
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

    name = kwargs["machine"]
    block, plan, result = curve_run(input, machine_from(kwargs), method, dialect, curve_index)
    plotting.plot_run(output, plan, result, run_series(block, plan, result), block.units,
                      name)


def run() -> None:
    """The console script: `main` in a process that ends when it returns.

    Everything imported by now, numba's ~100k objects among it, lives as long as the process;
    frozen, the garbage collector never walks it again, which saves ~0.2 s of interpreter
    teardown per run (measured by tests/bench/run.py's cold start).
    """
    gc.freeze()
    main()


if __name__ == "__main__":  # pragma: no cover
    run()
