"""Files as people handle them: batches that meet a crash, outputs that would overwrite an input
or each other, devices, links, FIFOs, signals, closed and broken pipes. Each case ends in a clear
message and exit code, or in the right behaviour; nothing the user wrote is lost or overwritten,
and no temporary file is left behind."""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

import nurbsfeed.pipeline
from nurbsfeed import files
from nurbsfeed.cli import main
from nurbsfeed.errors import InputError, Interrupted
from nurbsfeed.files import InputFile, atomic_output, output_target
from tests.bench.programs import json_program
from tests.conftest import SAMPLES

QUARTER = SAMPLES / "quarter-circle.json"
CIRCLE = SAMPLES / "circle.json"
CLI = [sys.executable, "-m", "nurbsfeed.cli"]


def run(*args: object) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return result.exit_code, result.stdout, result.stderr


def listing(folder: Path) -> list[str]:
    return sorted(os.listdir(folder))


# ---- one bad file does not stop a batch ----

def crash_on(name: str, how):
    """convert_file, except for the input called `name`, where `how()` happens."""
    real = nurbsfeed.pipeline.convert_file

    def convert_file(source, *args, **kwargs):
        if Path(source).name == name:
            how()
        return real(source, *args, **kwargs)

    return convert_file


FORK_ONLY = pytest.mark.skipif(multiprocessing.get_start_method() != "fork",
                               reason="the workers must inherit the patched convert_file")


def boom() -> None:
    raise ZeroDivisionError("boom\nsecond line")


@pytest.mark.parametrize("jobs", ["1", pytest.param("2", marks=FORK_ONLY)])
def test_a_crash_in_one_file_fails_its_row_and_the_others_are_converted(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, jobs: str) -> None:
    crash = tmp_path / "crash.json"
    crash.write_bytes(QUARTER.read_bytes())
    monkeypatch.setattr(nurbsfeed.pipeline, "convert_file", crash_on("crash.json", boom))
    out = tmp_path / "out"
    code, _, stderr = run("convert", QUARTER, crash, CIRCLE, "-o", out, "--jobs", jobs)
    assert code == 2
    assert listing(out) == ["circle.nc", "quarter-circle.nc"]
    row = next(line for line in stderr.splitlines() if line.startswith(str(crash)))
    assert row.endswith("FAILED: internal error: ZeroDivisionError: boom second line")
    assert stderr.endswith("2 of 3 files converted\n")


def test_quiet_prints_only_the_files_that_failed(tmp_path: Path) -> None:
    """-q: nothing when all convert; when one fails, its line and the count, not the table."""
    bad = tmp_path / "bad.json"
    bad.write_text('{"curves": [')
    out = tmp_path / "out"
    assert run("convert", QUARTER, CIRCLE, "-o", out, "-q") == (0, "", "")
    code, stdout, stderr = run("convert", QUARTER, bad, CIRCLE, "-o", out, "-q")
    assert (code, stdout) == (2, "")
    assert stderr == (f"{bad}:1:13: not valid JSON: Expecting value\n"
                      "2 of 3 files converted\n")


def test_a_crash_converting_a_single_input_is_one_line_with_the_file(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(nurbsfeed.pipeline, "convert_file", crash_on(QUARTER.name, boom))
    out = tmp_path / "q.nc"
    assert run("convert", QUARTER, "-o", out) == (
        2, "", f"{QUARTER}: internal error: ZeroDivisionError: boom second line\n")
    assert listing(tmp_path) == []


@FORK_ONLY
def test_a_killed_worker_fails_only_the_file_that_killed_it(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The pool breaks and fails every file in flight; each is converted again alone, so only
    the file whose worker dies each time fails."""
    die = tmp_path / "die.json"
    die.write_bytes(QUARTER.read_bytes())
    inputs = [QUARTER, die, CIRCLE, SAMPLES / "butterfly.json"]
    monkeypatch.setattr(nurbsfeed.pipeline, "convert_file",
                        crash_on("die.json", lambda: os.kill(os.getpid(), signal.SIGKILL)))
    out = tmp_path / "out"
    code, _, stderr = run("convert", *inputs, "-o", out, "--jobs", "2")
    assert code == 2
    assert listing(out)[-3:] == ["butterfly.nc", "circle.nc", "quarter-circle.nc"]
    assert "FAILED: internal error: BrokenProcessPool: the worker process converting this " \
           "file died (killed by a signal, or out of memory)" in stderr
    assert stderr.endswith("3 of 4 files converted\n")


# ---- outputs that would overwrite an input or each other ----

def test_two_inputs_writing_the_same_output_refuse_the_batch(tmp_path: Path) -> None:
    for folder, name in [("d1", "x.nc"), ("d2", "x.nc"), ("d3", "x.json"), ("d3", "X.nc")]:
        (tmp_path / folder).mkdir(exist_ok=True)
        (tmp_path / folder / name).write_bytes(QUARTER.read_bytes())
    out = tmp_path / "out"
    for first, second in [("d1/x.nc", "d2/x.nc"), ("d3/x.json", "d1/x.nc"),
                          ("d3/X.nc", "d3/x.json")]:
        a, b = tmp_path / first, tmp_path / second
        code, _, stderr = run("convert", a, b, "-o", out)
        target = out / "x.nc"  # the second writer's name (X.nc and x.nc count as one)
        assert (code, stderr) == (2, f"{target}: both {a} and {b} would be written here "
                                     "(rename one, or convert them in separate runs)\n")
        assert not out.exists()  # refused before anything was converted or created


def test_the_same_input_given_twice_is_named_as_such(tmp_path: Path) -> None:
    """Twice by the same name, or by another (a directory, a path through ..): the message
    says the input is given twice, not that two files would write one output. (A link of
    another name is an input of its own: it writes an output of its own.)"""
    (tmp_path / "d1").mkdir()
    src = tmp_path / "d1" / "x.nc"
    src.write_bytes(QUARTER.read_bytes())
    out = tmp_path / "out"
    for again in [src, tmp_path / "d1"]:  # the directory lists it by the same name
        assert run("convert", src, again, "-o", out) == (
            2, "", f"{src}: this input is given twice: give each input once (a directory and a "
                   "glob can both name it)\n")
    up = tmp_path / "d1" / ".."
    for second in [up / "d1" / "x.nc", up / ".." / tmp_path.name / "d1" / "x.nc"]:
        assert run("convert", src, second, "-o", out) == (
            2, "", f"{second}: this input is given twice (as {src} and as {second}): give each "
                   "input once (a directory and a glob can both name it)\n")
    assert not out.exists()


def test_an_output_that_is_an_input_is_refused_by_any_name(tmp_path: Path) -> None:
    src = tmp_path / "part.json"
    src.write_bytes(QUARTER.read_bytes())
    (tmp_path / "hard.nc").hardlink_to(src)
    (tmp_path / "soft.nc").symlink_to(src.name)
    other = tmp_path / "sub" / ".." / "part.json"
    (tmp_path / "sub").mkdir()
    for target in [src, other, tmp_path / "hard.nc", tmp_path / "soft.nc"]:
        assert run("convert", src, "-o", target) == (
            2, "", f"{target}: -o would overwrite the input {src}\n")
        assert run("convert", src, "-o", tmp_path / "a.nc", "--trace", target) == (
            2, "", f"{target}: --trace would overwrite the input {src}\n")
    trace = tmp_path / "." / "t.csv"
    assert run("convert", src, "-o", tmp_path / "t.csv", "--trace", trace) == (
        2, "", f"{trace}: -o and --trace name the same file\n")
    # in a directory: x.json's output x.nc is another input
    (tmp_path / "sub" / "x.json").write_bytes(QUARTER.read_bytes())
    (tmp_path / "sub" / "x.nc").write_bytes(b"G0 X1\n")
    code, _, stderr = run("convert", tmp_path / "sub", "-o", tmp_path / "sub")
    assert (code, stderr) == (2, f"{tmp_path / 'sub' / 'x.nc'}: the output of "
                                 f"{tmp_path / 'sub' / 'x.json'} would overwrite the input "
                                 f"{tmp_path / 'sub' / 'x.nc'}\n")
    assert src.read_bytes() == QUARTER.read_bytes()
    assert (tmp_path / "sub" / "x.nc").read_bytes() == b"G0 X1\n"
    assert listing(tmp_path) == ["hard.nc", "part.json", "soft.nc", "sub"]


def test_plot_refuses_to_overwrite_its_input_and_a_missing_directory(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    src = tmp_path / "c.json"
    src.write_bytes(QUARTER.read_bytes())
    assert run("plot", src, "-o", src) == (2, "", f"{src}: -o would overwrite the input {src}\n")
    target = tmp_path / "missing" / "dir" / "x.png"
    assert run("plot", src, "-o", target) == (
        2, "", f"{target}: cannot write output: directory {target.parent} does not exist\n")


# ---- what an output path may be ----

def test_output_kinds(tmp_path: Path) -> None:
    """Replaced atomically: a new name, a regular file, the file behind a symbolic link.
    Written through: character devices, FIFOs, names of descriptors. Refused: the rest."""
    (tmp_path / "file.nc").write_text("old")
    (tmp_path / "link.nc").symlink_to("file.nc")
    (tmp_path / "dangling.nc").symlink_to("nowhere.nc")
    os.mkfifo(tmp_path / "fifo")
    with socket.socket(socket.AF_UNIX) as sock:
        sock.bind(str(tmp_path / "sock"))
        assert output_target(tmp_path / "new.nc") == (tmp_path / "new.nc", False)
        assert output_target(tmp_path / "file.nc") == (tmp_path / "file.nc", False)
        assert output_target(tmp_path / "link.nc") == (tmp_path / "file.nc", False)
        assert output_target(Path("/dev/null")) == (Path("/dev/null"), True)
        assert output_target(tmp_path / "fifo") == (tmp_path / "fifo", True)
        assert output_target(Path("/dev/stdout"))[1]
        for name, message in [
                ("dangling.nc", "cannot write output: a symbolic link to nowhere.nc, which does "
                                "not exist"),
                ("sock", "cannot write output: it is a socket (nurbsfeed writes regular files, "
                         "character devices and FIFOs)"),
                ("missing/x.nc", f"cannot write output: directory {tmp_path / 'missing'} does "
                                 "not exist"),
                ("file.nc/x.nc", "cannot write output (Not a directory)")]:
            with pytest.raises(InputError) as info:
                output_target(tmp_path / name)
            assert str(info.value) == f"{tmp_path / name}: {message}"
        with pytest.raises(InputError, match="it is a directory"):
            output_target(tmp_path)


def test_a_symbolic_link_output_replaces_the_file_it_points_to(tmp_path: Path) -> None:
    (tmp_path / "file.nc").write_text("old")
    (tmp_path / "link.nc").symlink_to("file.nc")
    assert run("convert", QUARTER, "-o", tmp_path / "link.nc", "-q")[0] == 0
    assert (tmp_path / "link.nc").is_symlink()
    assert (tmp_path / "file.nc").read_bytes() == run("convert", QUARTER)[1].encode()
    assert listing(tmp_path) == ["file.nc", "link.nc"]


def test_a_fifo_output_is_written_into_not_replaced(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    code = run("convert", QUARTER, "-o", fifo, "-q")[0]
    reader.join(timeout=30)
    assert code == 0 and fifo.is_fifo() and listing(tmp_path) == ["fifo"]
    assert received == [run("convert", QUARTER)[1].encode()]


def test_dev_stdout_appends_to_what_the_shell_opened(tmp_path: Path) -> None:
    """`-o /dev/stdout >> log` writes into the log; replacing the file would lose its lines."""
    log = tmp_path / "log"
    log.write_bytes(b"kept\n")
    with open(log, "ab") as handle:
        subprocess.run(CLI + ["convert", str(QUARTER), "-o", "/dev/stdout", "-q"],
                       stdout=handle, check=True)
    assert log.read_bytes() == b"kept\n" + run("convert", QUARTER)[1].encode()


# ---- a failed or interrupted run leaves nothing, and what was there untouched ----

def test_a_failing_conversion_leaves_the_existing_output_and_trace_untouched(
        tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"degree": 1, "knots": [0,0,1,1], "control_points": [[0,0],[1,NaN]]}')
    out, trace = tmp_path / "out.nc", tmp_path / "t.csv"
    out.write_text("the previous good program\n")
    trace.write_text("the previous trace\n")
    code, _, stderr = run("convert", bad, "-o", out, "--trace", trace)
    assert code == 2 and stderr.startswith(f"{bad}:1:")
    assert out.read_text() == "the previous good program\n"
    assert trace.read_text() == "the previous trace\n"
    assert listing(tmp_path) == ["bad.json", "out.nc", "t.csv"]
    missing = tmp_path / "missing" / "t.csv"
    assert run("convert", QUARTER, "-o", out, "--trace", missing) == (
        2, "", f"{missing}: cannot write output: directory {missing.parent} does not exist\n")
    assert out.read_text() == "the previous good program\n"


@pytest.mark.parametrize("exc", [OSError(28, "No space left on device"), Interrupted(15),
                                 KeyboardInterrupt()])
def test_atomic_output_removes_its_temporary_file_on_every_way_out(tmp_path: Path,
                                                                   exc: BaseException) -> None:
    target = tmp_path / "out.nc"
    target.write_text("before")
    with pytest.raises(type(exc)), atomic_output(target) as out:
        out.write(b"partial")
        raise exc
    assert listing(tmp_path) == ["out.nc"] and target.read_text() == "before"
    with atomic_output(target) as out:
        out.write(b"after")
    assert listing(tmp_path) == ["out.nc"] and target.read_text() == "after"


@pytest.fixture(scope="module")
def long_program(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A program that takes a few seconds to convert: time to be signalled mid-way."""
    path = tmp_path_factory.mktemp("long") / "long.json"
    path.write_text(json_program(400))
    return path


def _default_signals() -> None:
    """The signals the tests send at their default disposition in the child, however the tests
    run: in the background SIGINT is ignored, under nohup SIGHUP (the child inherits it, and
    keeps ignoring it as nohup means)."""
    for signum in (signal.SIGINT, signal.SIGHUP, signal.SIGTERM):
        signal.signal(signum, signal.SIG_DFL)


def start_and_signal(args: list[str], folder: Path, signum: int, parts: int = 1) -> tuple[
        int, str]:
    """Run the CLI, wait until `parts` temporary outputs exist in `folder`, send `signum`."""
    proc = subprocess.Popen(CLI + args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_default_signals)
    deadline = time.monotonic() + 60
    while sum(name.endswith(".part") for name in os.listdir(folder)) < parts:
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.02)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=60)
    return proc.returncode, stderr


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130),
                                              (signal.SIGHUP, 129)])
def test_a_signal_mid_conversion_removes_the_temporary_files(
        tmp_path: Path, long_program: Path, signum: int, code: int) -> None:
    out = tmp_path / "out.nc"
    returncode, stderr = start_and_signal(
        ["convert", str(long_program), "-o", str(out), "--trace", str(tmp_path / "t.csv")],
        tmp_path, signum, parts=2)
    assert (returncode, stderr) == (code, f"nurbsfeed: stopped by {signum.name}\n")
    assert listing(tmp_path) == []


def test_a_signal_inside_the_call_that_creates_the_temporary_file_leaves_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The handler can run between the file's creation and its name reaching Python (another
    thread takes the signal, so no mask keeps it out): the name is held before the file exists."""
    real_open = os.open

    def open_then_stopped(name: str, flags: int, mode: int = 0o777) -> int:
        os.close(real_open(name, flags, mode))
        raise Interrupted(signal.SIGTERM)

    monkeypatch.setattr(files.os, "open", open_then_stopped)
    with pytest.raises(Interrupted), atomic_output(tmp_path / "out.nc"):
        pass
    assert listing(tmp_path) == [] and not files._LIVE


def test_a_signal_stops_every_worker_of_a_parallel_batch(tmp_path: Path,
                                                         long_program: Path) -> None:
    """Only the parent is signalled (as by `kill PID`): it stops its workers, which remove their
    temporary files; nothing more is converted."""
    out = tmp_path / "out"
    out.mkdir()
    inputs = []
    for name in "abc":
        inputs.append(tmp_path / f"{name}.json")
        inputs[-1].symlink_to(long_program)
    returncode, stderr = start_and_signal(["convert", *map(str, inputs), "-o", str(out),
                                           "--jobs", "2", "-q"], out, signal.SIGTERM, parts=2)
    assert (returncode, stderr) == (143, "nurbsfeed: stopped by SIGTERM\n")
    assert listing(out) == []


# ---- stdout closed or gone ----

def test_a_closed_stdout_is_a_message_not_a_traceback() -> None:
    done = subprocess.run(CLI + ["convert", str(QUARTER)], stderr=subprocess.PIPE, text=True,
                          preexec_fn=lambda: os.close(1))
    assert (done.returncode, done.stderr) == (
        2, "-: cannot write output (standard output is closed)\n")


@pytest.mark.parametrize("command", ["convert", "plan"])
def test_a_reader_that_goes_away_ends_the_run_quietly_with_141(tmp_path: Path,
                                                               command: str) -> None:
    """Like `nurbsfeed convert big.json | head -1`: exit 141, as a tool killed by SIGPIPE."""
    big = tmp_path / "big.json"
    big.write_text(json_program(40))
    proc = subprocess.Popen(CLI + [command, str(big)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stdout.readline()
    proc.stdout.close()
    _, stderr = proc.communicate(timeout=60)
    assert (proc.returncode, stderr) == (141, b"")


# ---- input read as lines ----

LINE_BYTES = st.lists(st.sampled_from([b"G1 X1\n", b"\r\n", b"\r", b"\n", b"\xe9", b"\xff\xfe",
                                       "\u00e9\u20ac".encode(), b"\xef\xbb\xbf", b"%", b""]))


@given(LINE_BYTES)
def test_lines_give_back_every_byte_and_end_only_where_a_line_ends(pieces: list[bytes]) -> None:
    content = b"".join(pieces)
    lines = list(InputFile(Path("t.nc"), content).lines())
    assert b"".join(line.encode("utf-8", "surrogateescape") for line in lines) == content
    newline = "\r" if b"\n" not in content and b"\r" in content else "\n"
    assert all(line.endswith(newline) for line in lines[:-1])
    assert all(newline not in line[:-1] for line in lines)


def test_a_file_of_cr_line_endings_reads_as_lines_and_a_later_lf_is_refused(
        monkeypatch: pytest.MonkeyPatch) -> None:
    assert list(InputFile(Path("t.nc"), b"G0 X1\rG1 X2\rM30").lines()) == [
        "G0 X1\r", "G1 X2\r", "M30"]
    # decided from the first LOOK_AHEAD_BYTES: a LF after them is not guessed at
    monkeypatch.setattr(files, "LOOK_AHEAD_BYTES", 8)
    lines = InputFile(Path("t.nc"), b"G0 X1\rG1 X2\rG1 X3\r\nM30\r").lines()
    assert [next(lines), next(lines), next(lines)] == ["G0 X1\r", "G1 X2\r", "G1 X3\r"]
    with pytest.raises(InputError) as caught:
        next(lines)
    assert str(caught.value) == ("t.nc:4:1: a line ending in LF in a file whose lines end in CR "
                                 "alone (classic Mac OS): write every line ending the same way")


def test_a_program_from_a_pipe_converts_like_the_file(tmp_path: Path) -> None:
    """`nurbsfeed convert <(command)`: a pipe is read once, whole, however often it is read."""
    for sample in (SAMPLES / "fanuc-quadratic.nc", QUARTER):
        read_end, write_end = os.pipe()
        writer = threading.Thread(target=lambda end=write_end, source=sample: (
            os.write(end, source.read_bytes()), os.close(end)))
        writer.start()
        try:
            piped = tmp_path / f"piped-{sample.name}.nc"
            code, _, stderr = run("convert", f"/dev/fd/{read_end}", "-o", piped, "-q")
        finally:
            writer.join()
            os.close(read_end)
        assert (code, stderr) == (0, "")
        direct = tmp_path / f"direct-{sample.name}.nc"
        assert run("convert", sample, "-o", direct, "-q")[0] == 0
        assert piped.read_bytes() == direct.read_bytes().replace(
            sample.name.encode(), f"{read_end}".encode())
