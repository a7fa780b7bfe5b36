"""The property every fuzz case must satisfy, checked through the command line only.

A case is an input file (and optionally a machine profile). `nurbsfeed convert IN -o OUT` runs
in this process (a case costs milliseconds, not a process start-up) under a time limit, and must
end in one of two ways:

- exit 0: OUT is a program whose lines outside the replaced NURBS blocks are the input's lines,
  byte for byte and in order, and whose generated moves write every number with a decimal point;
- exit 2: one message on stderr located at the input or the profile (`FILE:LINE:COL: ...`, or
  `FILE: ...` where no line applies), and no OUT.

Never a traceback, an "internal error", a hang, or a temporary `.part` file left behind.

The pass-through check knows the output format, not the reader: nurbsfeed writes, in place of a
block, a `(nurbsfeed: curve ...)` comment and then only lines of its own forms (`G90`, `G91`, G1
moves, an F restore). Those are taken off the output; what remains must be found in the input in
order, and every input line left out must be one a NURBS block consumes (it carries a NURBS G
code or a K, P, L, R or F word). Since a pass-through `G90` or `X5.` right after a block looks like
generated text, each block's run of generated lines is tried from its longest reading down.
"""

from __future__ import annotations

import io
import re
import signal
import time
from contextlib import redirect_stderr
from dataclasses import dataclass
from pathlib import Path

from nurbsfeed.cli import main

# CPU seconds a case may take (`check_case`): TIME_LIMIT_S, and LINE_CPU_S more for each line
# it writes. The default's planner converts at 20-90 us a point (docs/benchmarks.md), so a valid
# program of 392,606 points (a curve of 196 s at 5 mm/s, twice) took 11.6 s: a flat limit
# calls a long output slow, while a case slow for its size (a planner gone superlinear) still
# shows. A conversion stops at CEILING_S whatever it writes (`run_cli`'s limit).
TIME_LIMIT_S = 10.0
LINE_CPU_S = 100e-6
CEILING_S = 120.0
CHECK_TIME_LIMIT_S = 60.0  # `check` of a slow inch curve (70,000 moves) takes seconds
# nurbsfeed's comment lines, in parentheses or, in a Sinumerik program, after ';'
CURVE_COMMENT = (b"(nurbsfeed: curve ", b"; nurbsfeed: curve ",
                 b"(nurbsfeed: curves ", b"; nurbsfeed: curves ")
# a chain's comment (design §3b): the lines read between its curves come among its moves
CHAIN_COMMENT = re.compile(rb"(?:\(|; )nurbsfeed: curves \d+-\d+ chained,")
# the profile record (gcode.profile_record), in either form
PROFILE_RECORD = (b"(nurbsfeed profile: ", b"; nurbsfeed profile: ")
ZERO_LENGTH = (b"(nurbsfeed: zero-length curve, no move written)",
               b"; nurbsfeed: zero-length curve, no move written")
_MOVE_WORD = rb"[XYZF]-?[0-9]*\.?[0-9]*"
_GENERATED = re.compile(rb"(?:G1 )?" + _MOVE_WORD + rb"(?: " + _MOVE_WORD + rb")*|G90|G91")
_NUMBER = re.compile(rb"[XYZF](-?[0-9]*\.?[0-9]*)")
_COMMENT = re.compile(rb"\([^)]*\)|;.*")
# A generated move whose every number has its point, digits, and is not "-0.": a line that
# passes both _GENERATED and _bad_numbers, matched at once (the bulk of a JSON input's output,
# tens of thousands of lines a case; a line it does not match takes the full check).
_POINTED = rb"[XYZF](?!-0\.(?![0-9]))-?(?:[0-9]+\.[0-9]*|\.[0-9]+)"
_GOOD_MOVE = re.compile(rb"(?:G0 )?(?:G1 )?" + _POINTED + rb"(?: " + _POINTED + rb")*")
# A line a NURBS block consumes (and nurbsfeed therefore drops): a NURBS G code (G5.2, G5.3,
# G6.2, and LinuxCNC's G5 / G5.1 splines), or a word only NURBS blocks carry (a BSPLINE and its
# PL, PW words among them), or a lone F (LinuxCNC allows one on a line of a G5.2 block). Spaces
# are the tokenizer's: a lone CR inside a line is one ("G\r5.3" is G5.3).
_BLOCK_LINE = re.compile(rb"[Gg][ \t\r]*0*[56][ \t\r]*\.[ \t\r]*[23]|[KkPpLlRrQq]"
                         rb"|[Gg][ \t\r]*0*5(?:[ \t\r]*\.[ \t\r]*1)?(?![ \t\r]*\.?[ \t\r]*[0-9])"
                         rb"|^[ \t\r]*(?:[Nn][ \t\r]*[0-9]+[ \t\r]*)?[Ff]")
_LOCATED = r"^{}(?::\d+:\d+)?: \S"


class CaseTimeout(BaseException):
    """The case ran past its time limit (a BaseException: the CLI's `except Exception`, which
    turns a crash into an "internal error" row, must not swallow it)."""


@dataclass(frozen=True)
class Outcome:
    exit_code: int | None
    stderr: str
    problem: str | None  # None: the case satisfies the property

    @property
    def converted(self) -> bool:
        return self.problem is None and self.exit_code == 0


_armed = False  # a case is running: the alarm may stop it
_fired = False  # ... and it did
last_cpu_s = 0.0  # the CPU time of the last `run_cli`


def _alarm(signum: int, frame: object) -> None:
    global _fired
    if _armed:
        _fired = True
        raise CaseTimeout


def run_cli(args: list[str], time_limit_s: float | None = None) -> tuple[int | None, str, str]:
    """nurbsfeed ARGS in this process: (exit code, stderr, traceback text or "")."""
    time_limit_s = TIME_LIMIT_S if time_limit_s is None else time_limit_s
    import traceback

    global _armed, _fired, last_cpu_s
    stderr = io.StringIO()
    _fired = False
    started = time.process_time()
    previous = signal.signal(signal.SIGPROF, _alarm)
    code: int | None
    crash = ""
    try:
        _armed = True
        # the process's CPU time, not the wall clock: on a loaded machine (two fuzz jobs beside
        # a test suite) a 2 s case took 13 s of wall time and was reported as a time-out;
        # repeated each second: a signal arriving while numba's cache runs Python code is lost
        signal.setitimer(signal.ITIMER_PROF, time_limit_s, 1.0)
        with redirect_stderr(stderr):
            try:
                main(args, standalone_mode=False)
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except CaseTimeout:
        _fired = True
    except BaseException:  # noqa: BLE001 - anything escaping the CLI is what we look for
        code, crash = None, traceback.format_exc()
    finally:
        _armed = False
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)
        last_cpu_s = time.process_time() - started
    if _fired:
        # raised inside compiled code, the time-out can reach the CLI wrapped (numba's
        # dispatcher returns it as a SystemError, which the CLI reports as an internal error)
        code, crash = None, f"timeout: more than {time_limit_s:g} s of CPU"
    return code, stderr.getvalue(), crash


def case_budget_s(lines: int) -> float:
    """The CPU seconds a case that writes `lines` lines may take (TIME_LIMIT_S, LINE_CPU_S)."""
    return TIME_LIMIT_S + LINE_CPU_S * lines


def split_lines(data: bytes) -> list[bytes]:
    """Lines with their endings, as the reader splits them ("\\r" ends lines only in a file
    without "\\n")."""
    newline = b"\r" if b"\n" not in data and b"\r" in data else b"\n"
    pieces = data.split(newline)
    lines = [piece + newline for piece in pieces[:-1]]
    return lines + [pieces[-1]] if pieces[-1] else lines


def _bare(line: bytes) -> bytes:
    return line.rstrip(b"\r\n")


def _block_line(line: bytes) -> bool:
    return bool(_BLOCK_LINE.search(_COMMENT.sub(b"", line)))


def _generated(line: bytes) -> bool:
    return bool(_GENERATED.fullmatch(_bare(line))) or _bare(line) in ZERO_LENGTH


def _match(literal: list[bytes], source: list[bytes], at: int) -> int | None:
    """Find `literal` in `source` from `at` on, in order, skipping only block lines: the index
    after the last match, or None. The earliest match is always the best one."""
    for line in literal:
        while at < len(source) and source[at] != line:
            if not _block_line(source[at]):
                return None
            at += 1
        if at == len(source):
            return None
        at += 1
    return at


def pass_through_problem(source: bytes, output: bytes) -> str | None:
    """None when the output is the source with NURBS blocks replaced, else what is wrong."""
    src = split_lines(source)
    out = split_lines(output)
    if source.startswith(b"\xef\xbb\xbf"):
        if not output.startswith(b"\xef\xbb\xbf"):
            return "the BOM was not kept"
        src[0] = src[0][3:]
        out[0] = out[0][3:]
    segments: list[list[bytes]] = [[]]
    chains = [False]
    for line in out:
        if line.startswith(CURVE_COMMENT):
            segments.append([])
            chains.append(bool(CHAIN_COMMENT.match(line)))
        else:
            segments[-1].append(line)
    # the profile record: nurbsfeed's own lines just before the first curve's comment
    while len(segments) > 1 and segments[0] and segments[0][-1].startswith(PROFILE_RECORD):
        segments[0].pop()
    at = _match(segments[0], src, 0)
    if at is None:
        return _first_mismatch(segments[0], src, 0)
    known = set(src)
    # in a chain the moves run on after the lines of each joint: generated lines that are not
    # the input's are taken off wherever they are, up to the last one
    for i, chain in enumerate(chains):
        if chain:
            last = max((k for k, line in enumerate(segments[i])
                        if _generated(line) and line not in known), default=-1)
            segments[i] = [line for k, line in enumerate(segments[i])
                           if k > last or not (_generated(line) and line not in known)]
    choices = []  # per block: how many of its segment's first lines may be generated
    for segment in segments[1:]:
        longest = 0
        while longest < len(segment) and _generated(segment[longest]):
            longest += 1
        shortest = longest  # generated lines that are not in the input cannot pass through
        while shortest > 0 and segment[shortest - 1] in known:
            shortest -= 1
        choices.append(range(longest, shortest - 1, -1))
        bad = _bad_numbers(segment[:shortest])
        if bad:
            return f"a generated line writes a number without its point: {bad!r}"
    if _align(segments[1:], choices, src, at):
        return None
    return "the output is not the input with its NURBS blocks replaced (" + (
        _first_mismatch([line for segment in segments[1:] for line in segment
                         if not _generated(line)], src, at) + ")")


def _align(segments: list[list[bytes]], choices: list[range], source: list[bytes], at: int
           ) -> bool:
    """Whether each segment, less some of its first lines (taken as generated), follows in
    `source` from `at` on, and what remains of `source` is block lines (depth-first search)."""
    if not segments:
        return all(_block_line(line) for line in source[at:])
    for generated in choices[0]:
        found = _match(segments[0][generated:], source, at)
        if found is not None and _align(segments[1:], choices[1:], source, found):
            return True
    return False


def _first_mismatch(literal: list[bytes], source: list[bytes], at: int) -> str:
    for line in literal:
        found = _match([line], source, at)
        if found is None:
            return f"output line not in the input where expected: {line!r}"
        at = found
    return "lines out of order"


def _bad_numbers(lines: list[bytes]) -> bytes | None:
    for line in lines:
        for number in _NUMBER.findall(line):
            if b"." not in number or number in (b"-0.", b"-.") or number.strip(b"-.") == b"":
                return _bare(line)
    return None


def json_program_problem(output: bytes) -> str | None:
    """A JSON input's output: header comment, units and G90, then G0 to each curve start, the
    curves and M2; every G0/G1 number written with its point."""
    lines = [_bare(line) for line in split_lines(output)]
    if not lines or not lines[0].startswith(b"(nurbsfeed: ") or lines[1] not in (b"G21 G90",
                                                                                 b"G20 G90"):
        return f"not a program header: {lines[:2]!r}"
    for line in lines[2:]:
        if _GOOD_MOVE.fullmatch(line):
            continue
        if line.startswith(b"(") and line.endswith(b")") or line == b"M2":
            continue
        if line.startswith(b"G0 "):
            line = line[3:]
        if not _GENERATED.fullmatch(line) or _bad_numbers([line]):
            return f"unexpected line: {line!r}"
    return None


def check_case(folder: Path, source_name: str, data: bytes, profile: bytes | None = None,
               check_motion: bool = False) -> Outcome:
    """Write the case into `folder` (emptied first), convert it, and check the property."""
    for old in folder.iterdir():
        old.unlink()
    source = folder / source_name
    source.write_bytes(data)
    target = folder / "out.nc"
    args = ["convert", str(source), "-o", str(target), "--quiet"]
    expected = {source.name, target.name}
    machine = None
    if profile is not None:
        machine = folder / "machine.yaml"
        machine.write_bytes(profile)
        args += ["--machine", str(machine)]
        expected.add(machine.name)
    code, stderr, crash = run_cli(args, CEILING_S)
    left = sorted(p.name for p in folder.iterdir() if p.name not in expected)
    problem = None
    output = target.read_bytes() if code == 0 and target.exists() else b""
    lines = output.count(b"\n")
    if not crash and last_cpu_s > case_budget_s(lines):
        crash = (f"timeout: {last_cpu_s:.1f} s of CPU for {lines} lines written, more than "
                 f"{case_budget_s(lines):.1f} s")
    if crash:
        problem = crash.strip().splitlines()[-1] if crash.startswith("timeout") else crash
    elif "Traceback" in stderr or "internal error" in stderr:
        problem = "crash reported on stderr: " + stderr.strip()
    elif left:
        problem = f"files left behind: {left}"
    elif code == 2:
        places = [re.escape(str(source))] + ([re.escape(str(machine))] if machine else [])
        if target.exists():
            problem = "exit 2 but an output file was written"
        elif not any(re.match(_LOCATED.format(place), stderr) for place in places):
            problem = f"exit 2 without a located message: {stderr.strip()!r}"
        elif stderr.count("\n") != 1:
            problem = f"exit 2 with more than one line on stderr: {stderr!r}"
    elif code == 0:
        if not target.exists():
            problem = "exit 0 without an output file"
        else:
            # the reader's rule (docs/programs.md, Inputs): a .json file, or any whose first
            # character other than white space is "{" (a sample spliced whole into an .ngc is JSON)
            is_json = source.suffix.lower() == ".json" or data.lstrip().startswith(b"{")
            problem = (json_program_problem(output) if is_json
                       else pass_through_problem(data, output))
            if problem is None and check_motion:
                problem = motion_problem(source, target, machine)
    else:
        problem = f"exit {code}: {stderr.strip()!r}"
    return Outcome(code, stderr, problem)


def motion_problem(source: Path, target: Path, machine: Path | None) -> str | None:
    """`nurbsfeed check SOURCE OUTPUT`: the moves stay on the curve, within the limits."""
    args = ["check", str(source), str(target)] + (["--machine", str(machine)] if machine else [])
    out = io.StringIO()
    from contextlib import redirect_stdout

    with redirect_stdout(out):
        code, stderr, crash = run_cli(args, CHECK_TIME_LIMIT_S)
    if crash or code != 0:
        return f"nurbsfeed check: exit {code}: {(crash or stderr or out.getvalue()).strip()}"
    return None

