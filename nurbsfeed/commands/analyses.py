"""The analyses' commands: `compare` (the paper's Table 2 on any input), `check` (a converted
program verified against its source, under the profile recorded in it) and `plot` (the
paper's figures for one curve, matplotlib). Each calls nurbsfeed.analysis and prints its report.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from nurbsfeed.commands.batch import file_id, same_file
from nurbsfeed.commands.common import (
    OVERRIDE_KEYS,
    dialect_option,
    epilog,
    machine_from,
    machine_options,
    method_option,
    reports_errors,
)
from nurbsfeed.commands.warm_up import hand_off, profile_options, warm_up
from nurbsfeed.errors import EXIT_BAD_INPUT, InputError, Location, ProfileError
from nurbsfeed.machine import machine_from_mapping

if TYPE_CHECKING:
    from nurbsfeed.machine import Machine

PLOT_NEEDS_MATPLOTLIB = "nurbsfeed plot needs matplotlib: pip install 'nurbsfeed[plot]'"


@click.command(epilog=epilog(
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
    hand_off(warm_up("compare", profile_options(kwargs)))
    result = compare_file(input, machine_from(kwargs), dialect, repeat)
    click.echo(json.dumps(dict(result.as_dict(), machine=name), indent=2) if as_json
               else render_comparison(result, name))


@click.command(epilog=epilog(
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


@click.command(epilog=epilog(
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

    if file_id(output) is not None and same_file(input, output):
        raise InputError(f"-o would overwrite the input {input}", Location(str(output)))
    output_target(output)  # refused now, not after the run
    name = kwargs["machine"]
    hand_off(warm_up("plot", [*profile_options(kwargs), "--method", method]))
    block, plan, result = curve_run(input, machine_from(kwargs), method, dialect, curve_index)
    try:
        plotting.plot_run(output, plan, result, run_series(block, plan, result), name)
    except OSError as exc:
        raise InputError(f"cannot write output ({exc.strerror or exc})",
                         Location(str(output))) from None

