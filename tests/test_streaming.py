"""Work and memory bounded (issue 11): a curve is stepped and written chunk by chunk, with the
same output to the last byte as in one piece; a curve planned to run longer than
max_curve_time_s is refused before any stepping."""

from __future__ import annotations

import io
import json
import math
import subprocess
import sys
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from nurbsfeed import pipeline, verified
from nurbsfeed.errors import CurveError
from nurbsfeed.interpolate import stepping as stepping_module
from nurbsfeed.interpolate.landing import BUMP_PERIODS
from nurbsfeed.interpolate.stepping import Stepping, interpolate
from nurbsfeed.machine import load_machine
from nurbsfeed.pipeline import convert_block, convert_file, plan_block
from nurbsfeed.planning.limits import Limits
from nurbsfeed.planning.planner import plan_curve
from nurbsfeed.planning.scurve_plan import MAX_STRETCH_PERIODS, _whole_periods
from nurbsfeed.program import CurveBlock
from nurbsfeed.safety import PointReader
from tests.conftest import ROOT, SAMPLES
from tests.test_cli import run
from tests.test_planning_interpolation import line

SMALL_CHUNK = 97  # odd: chunk edges fall anywhere, bumps straddle them
CHECKED_BLOCK = pipeline._checked_block  # the planning a measurement patches out


def curve_json(name: str, degree: int, knots, points, feed_mm_min: float) -> dict:
    return {"name": name, "degree": degree, "knots": knots, "control_points": points,
            "feed": feed_mm_min}


def many_period_program(tmp_path: Path) -> Path:
    """Curves of a few thousand periods each, every kind of landing: a corner (two stretches
    between rests), arcs that land with a bump, a line too short to cruise (sigma alone), a
    zero-length curve, and an arc programmed in inches."""
    quarter = curve_json("arc", 2, [0, 0, 0, 1, 1, 1], [[10, 0], [10, 10], [0, 10]], 600)
    quarter["weights"] = [1, math.sqrt(0.5), 1]
    curves = [
        curve_json("corner", 2, [0, 0, 0, 0.5, 0.5, 1, 1, 1],
                   [[0, 10], [10, 10], [20, 10], [20, 20], [20, 30]], 900),
        quarter,
        curve_json("short", 1, [0, 0, 1, 1], [[20, 30], [21, 30]], 600),
        curve_json("dot", 1, [0, 0, 1, 1], [[21, 30], [21, 30]], 600),
        curve_json("cubic", 3, [0, 0, 0, 0, 0.5, 1, 1, 1, 1],
                   [[21, 30], [25, 35], [30, 28], [35, 36], [40, 30]], 1200),
    ]
    path = tmp_path / "many.json"
    path.write_text(json.dumps({"units": "mm", "curves": curves}))
    return path


def converted(source: Path, target: Path, method: str) -> tuple[bytes, bytes]:
    trace = target.with_suffix(".csv")
    convert_file(source, target, load_machine("paper-table1"), method, trace_path=trace)
    return target.read_bytes(), trace.read_bytes()


@pytest.mark.parametrize("method", ["rk2c", "rk4"])
def test_small_chunks_write_the_same_program_and_trace_as_one_chunk(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, method: str) -> None:
    source = many_period_program(tmp_path)
    whole = converted(source, tmp_path / "whole.nc", method)
    monkeypatch.setattr(stepping_module, "CHUNK_PERIODS", SMALL_CHUNK)
    chunked = converted(source, tmp_path / "chunked.nc", method)
    assert chunked[0] == whole[0]
    assert chunked[1] == whole[1]
    # the program really was stepped in many chunks, through every kind of landing
    machine = load_machine("paper-table1")
    blocks = [item.in_mm() for item in json_items(source) if isinstance(item, CurveBlock)]
    results = [interpolate(plan_block(b, machine), method) for b in blocks]
    periods = [r.n_points - 1 for r in results]
    assert min(p for p in periods if p) > SMALL_CHUNK and max(periods) > 20 * SMALL_CHUNK
    assert len(results[0].stretches) == 2  # the corner
    if method == "rk2c":
        bumps = [st.bump for r in results for st in r.stretches if st.slowdown > 0]
        assert any(b.k0 // SMALL_CHUNK != (b.k0 + BUMP_PERIODS) // SMALL_CHUNK for b in bumps)
        assert any(st.slowdown == 0 for r in results for st in r.stretches)  # by sigma alone


def json_items(path: Path):
    from nurbsfeed.readers import read_program

    return list(read_program(path))


def test_in_memory_interpolation_is_the_streamed_one(monkeypatch: pytest.MonkeyPatch,
                                                       paper_limits: Limits) -> None:
    """`interpolate` (the analyses) collects the chunks the conversion streams."""
    curve = line([[0, 0], [30, 5], [60, 0]], degree=2)
    plan = plan_curve(curve, paper_limits)
    whole = interpolate(plan)
    monkeypatch.setattr(stepping_module, "CHUNK_PERIODS", SMALL_CHUNK)
    chunks = list(Stepping(plan).chunks())
    assert len(chunks) > plan.n_periods // SMALL_CHUNK
    assert np.array_equal(np.concatenate([c.points for c in chunks]), whole.points)
    assert np.array_equal(np.concatenate([c.u for c in chunks]), whole.u)
    assert np.array_equal(np.concatenate([c.ds_mm for c in chunks])[1:], whole.ds_mm)
    v = np.concatenate([c.kinematics()[0] for c in chunks])
    assert np.array_equal(v, whole.v_mm_s)


@pytest.mark.parametrize("chunk", [stepping_module.CHUNK_PERIODS, SMALL_CHUNK])
def test_stepping_with_the_landings_found_steps_the_same_points(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, chunk: int) -> None:
    """A plan stepped again with the landings of a first stepping (as the conversion does with
    those of `verified_plan`'s look at the points) gives the same chunks to the last bit,
    through every kind of landing, in one chunk a stretch or many."""
    monkeypatch.setattr(stepping_module, "CHUNK_PERIODS", chunk)
    machine = load_machine("paper-table1")
    blocks = [item.in_mm() for item in json_items(many_period_program(tmp_path))
              if isinstance(item, CurveBlock)]
    for block in blocks:
        plan = plan_block(block, machine)
        first = Stepping(plan)
        searched = list(first.chunks())
        assert first.landed is not None
        again = Stepping(plan, landings=first.landed)
        replayed = list(again.chunks())
        assert again.landed == first.landed and again.runs == first.runs
        assert len(replayed) == len(searched)
        for a, b in zip(searched, replayed):
            assert a.k0 == b.k0 and a.local == b.local
            assert np.array_equal(a.u, b.u) and np.array_equal(a.points, b.points)
            assert np.array_equal(a.ds_mm, b.ds_mm)
            assert all(np.array_equal(x, y) for x, y in zip(a.kinematics(), b.kinematics()))


@pytest.mark.parametrize("kept_points", [verified.KEPT_POINTS, 100])
def test_the_points_read_for_the_plan_are_the_points_written(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kept_points: int) -> None:
    """Under the path model the conversion writes the points `verified` read (with their
    differences' readings, which the motion guard takes instead of its own) where there are at
    most KEPT_POINTS, else steps the plan again with its landings: the same program either way,
    and the same points and readings as a stepping of its own."""
    monkeypatch.setattr(verified, "KEPT_POINTS", kept_points)
    machine = load_machine("default")
    blocks = [item.in_mm() for item in json_items(many_period_program(tmp_path))
              if isinstance(item, CurveBlock)]
    out = io.BytesIO()
    for index, block in enumerate(blocks):
        checked = CHECKED_BLOCK(block, machine, "rk2c")
        assert checked.landings is not None
        kept = checked.kept
        assert (kept is None) == (1 + checked.plan.n_periods > kept_points)
        reader = PointReader()
        again = list(Stepping(checked.plan, landings=checked.landings).chunks())
        given = list(checked.chunks("rk2c"))
        assert len(given) == len(again)
        for (chunk, maxima), other in zip(given, again):
            assert np.array_equal(chunk.u, other.u) and np.array_equal(chunk.points, other.points)
            assert np.array_equal(chunk.ds_mm, other.ds_mm)
            _, read = reader.read(other.points)
            assert maxima is None or np.array_equal(maxima, read, equal_nan=True)
        convert_block(block, index, out, machine, "rk2c", None)
    monkeypatch.setattr(verified, "KEPT_POINTS", 0)
    again_out = io.BytesIO()
    for index, block in enumerate(blocks):
        convert_block(block, index, again_out, machine, "rk2c", None)
    assert out.getvalue() == again_out.getvalue()


def test_a_stepping_not_exhausted_has_not_landed(paper_limits: Limits) -> None:
    stepping = Stepping(plan_curve(line([[0, 0], [30, 5], [60, 0]], degree=2), paper_limits))
    chunks = stepping.chunks()
    next(chunks)
    next(chunks)
    assert stepping.landed is None
    list(chunks)
    assert stepping.landed is not None and len(stepping.landed) == len(stepping.stretches)


class Discard(io.RawIOBase):
    """An output that keeps nothing: what is measured is the conversion's own memory."""

    def writable(self) -> bool:
        return True

    def write(self, data) -> int:  # type: ignore[override]
        return len(data)


def peak_bytes(feed_mm_s: float, trace: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[int, int]:
    """Peak traced memory of converting the quarter circle at feed_mm_s once planned (the
    planner's grid is bounded on its own, by MAX_GRID_NODES); its periods."""
    machine = load_machine("paper-table1", {"max_feed_mm_s": feed_mm_s})
    block = next(item for item in json_items(SAMPLES / "quarter-circle.json")
                 if isinstance(item, CurveBlock))
    checked = CHECKED_BLOCK(block.in_mm(), machine, "rk2c")
    monkeypatch.setattr(pipeline, "_checked_block", lambda *_: checked)
    tracemalloc.start()
    try:
        result = convert_block(block, 0, Discard(), machine, "rk2c",
                               Discard() if trace else None)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return peak, result.n_points - 1


@pytest.mark.parametrize(("trace", "chunk", "feed_mm_s"), [(False, 2048, 1.0), (True, 256, 10.0)])
def test_memory_does_not_grow_with_the_duration_of_a_curve(
        monkeypatch: pytest.MonkeyPatch, trace: bool, chunk: int, feed_mm_s: float) -> None:
    """Ten times the periods, the same peak: chunks, not the curve, are held, in the program
    and in the trace. (Whole-curve arrays took ~90 bytes a period.)"""
    monkeypatch.setattr(stepping_module, "CHUNK_PERIODS", chunk)
    peak_bytes(feed_mm_s, trace, monkeypatch)  # compile and cache outside the measurement
    short, short_periods = peak_bytes(feed_mm_s, trace, monkeypatch)
    long, long_periods = peak_bytes(feed_mm_s / 10.0, trace, monkeypatch)
    assert long_periods > 9 * short_periods > 9 * 4 * chunk
    assert long < 1.5 * short
    assert long < 10 * long_periods  # far below the 90 bytes a period of whole-curve arrays


def test_a_curve_of_two_hours_converts_below_300_mb(tmp_path: Path) -> None:
    """The issue's bound, in a process of its own: a 7,854 s curve (7.9 million periods; whole-
    curve arrays took 0.8 GB) converts in less than 300 MB, and in no more than a curve of a
    hundredth of its duration (78,500 periods, stepped in chunks too) converted just before it
    in the same process. Compiling the kernels (a cold numba cache, as in a fresh clone) takes
    memory of its own, which the short conversion pays first."""
    script = (
        "import resource, sys\n"
        "from nurbsfeed.cli import main\n"
        "for feed in ('0.2', '0.002'):\n"
        "    try:\n"
        "        main(sys.argv[1:] + ['--max-feed-mm-s', feed])\n"
        "    except SystemExit as exc:\n"
        "        assert not exc.code, exc.code\n"
        "    print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n")
    out = tmp_path / "long.nc"
    done = subprocess.run(
        [sys.executable, "-c", script, "convert", str(SAMPLES / "quarter-circle.json"), "-q",
         "--max-curve-time-s", "10000", "-o", str(out)],
        check=True, capture_output=True, text=True)
    short_kb, long_kb = (int(x) for x in done.stdout.split()[-2:])
    assert long_kb < short_kb + 50_000, (short_kb, long_kb)  # 100x the periods: arrays took 0.7 GB
    assert long_kb < 300_000 or short_kb > 280_000, (short_kb, long_kb)  # (compiling: see above)
    comment = next(line for line in out.read_text().splitlines()
                   if line.startswith("(nurbsfeed: curve 0 "))
    assert "planned cycle 7853.9" in comment


def test_a_curve_longer_than_max_curve_time_is_refused_without_output(tmp_path: Path) -> None:
    source = SAMPLES / "quarter-circle.json"
    # the paper model: the path model refuses it earlier, on a lower bound ("cycle of at least")
    machine = load_machine("paper-table1", {"max_feed_mm_s": 1.0})
    block = next(item for item in json_items(source) if isinstance(item, CurveBlock))
    plan = plan_block(block.in_mm(), machine)  # 15.7 s
    out = tmp_path / "q.nc"
    code, stdout, stderr = run("convert", str(source), "-m", "paper-table1", "--max-feed-mm-s",
                               "1", "--max-curve-time-s", "10", "-o", str(out))
    assert (code, stdout) == (2, "")
    assert stderr == (f'{source}:2:44: curve 0 "quarter-circle-r10": planned cycle '
                      f"{plan.law.duration_s:.6g} s exceeds max_curve_time_s = 10 s (raise it "
                      "in the profile or with --max-curve-time-s)\n")
    assert not out.exists() and list(tmp_path.iterdir()) == []
    # both sides of the limit: the planned cycle itself passes, a hair less is refused
    code, _, _ = run("convert", str(source), "-m", "paper-table1", "--max-feed-mm-s", "1",
                     "--max-curve-time-s", repr(plan.cycle_time_s), "-o", str(out))
    assert code == 0 and out.exists()
    with pytest.raises(CurveError, match=r"^planned cycle .* exceeds max_curve_time_s"):
        plan_curve(block.curve, plan.limits, block.feed_u, block.feed_mm_s,
                   math.nextafter(plan.cycle_time_s, 0.0))


@pytest.mark.parametrize("duration_s", [1.4e29, math.inf, math.nan])
def test_an_absurd_duration_never_wraps_to_a_small_period_count(duration_s: float) -> None:
    """ceil(duration / T) into int64 wrapped: 1.4e29 s became one period (a straight G1
    across the curve at F1.7e6). Such a stretch gets -1, which the planner refuses."""
    v_key = np.array([0.0, 0.0])
    residual, _, periods, _ = _whole_periods(v_key, np.array([0.0, duration_s]),
                                             np.array([0, 2]), np.ones(3), np.zeros(3), 0.001, 1.0)
    assert residual == 1.0 and periods.tolist() == [-1]
    _, _, periods, _ = _whole_periods(v_key, np.array([0.0, MAX_STRETCH_PERIODS * 0.001]),
                                      np.array([0, 2]), np.ones(3), np.zeros(3), 0.001, 1.0)
    assert 0.99 * MAX_STRETCH_PERIODS < periods[0] <= MAX_STRETCH_PERIODS  # the longest allowed


def test_a_crawl_of_1e29_seconds_is_refused_even_without_a_time_limit(
        paper_limits: Limits) -> None:
    crawl = Limits(**{**vars(paper_limits), "feed_mm_s": 1e-28})
    with pytest.raises(CurveError, match=r"^planned cycle 1(\.\d+)?e\+29 s exceeds "
                                         r"max_curve_time_s = inf s"):
        plan_curve(line([[0, 0], [10, 0]]), crawl)


def test_max_curve_time_is_optional_in_a_profile_and_an_hour_by_default(tmp_path: Path) -> None:
    lines = (ROOT / "configs" / "paper-table1.yaml").read_text().splitlines()
    profile = tmp_path / "m.yaml"
    profile.write_text("\n".join(x for x in lines if not x.startswith("max_curve_time_s")))
    assert load_machine(str(profile)).max_curve_time_s == 3600.0
    assert load_machine("default").max_curve_time_s == 3600.0
    assert load_machine("paper-table1", {"max_curve_time_s": 60}).max_curve_time_s == 60.0


# ---- reading streams: memory does not grow with the number of input lines ----

class MeteredLines:
    """Program lines handed out one at a time, refusing any read past `allowed`."""

    def __init__(self, lines: list[str]) -> None:
        self.lines = lines
        self.read = 0
        self.allowed = 0

    def __iter__(self) -> MeteredLines:
        return self

    def __next__(self) -> str:
        if self.read == len(self.lines):
            raise StopIteration
        assert self.read < self.allowed, f"line {self.read + 1} read ahead of its item"
        self.read += 1
        return self.lines[self.read - 1]


def test_the_gcode_reader_reads_a_line_only_when_its_item_is_wanted() -> None:
    """A pass-through line is yielded before the next line is read; only inside a curve does the
    reader look ahead, RUN_LINES at most. So the lines held never depend on the file's length."""
    from nurbsfeed.gcode.point_lines import RUN_LINES
    from nurbsfeed.program import PassThrough
    from nurbsfeed.readers.gcode import read_gcode
    from tests.bench.programs import fanuc_program

    program = fanuc_program(1).splitlines(keepends=True)
    head, curve, tail = program[:5], program[5:-4], program[-4:]  # curve: G06.2 .. closing K
    filler = [f"(pass-through {i})\n" for i in range(2 * RUN_LINES)]
    lines = head + filler + curve + filler + tail
    first_curve_line = len(head + filler)
    source = MeteredLines(lines)
    stream = read_gcode(Path("t.nc"), source)
    items = []
    while True:
        # the item being read is the next line's, or the whole curve plus the look-ahead
        in_curve = first_curve_line <= source.read < first_curve_line + len(curve)
        source.allowed = (first_curve_line + len(curve) + RUN_LINES if in_curve
                          else source.read + 1)
        item = next(stream, None)
        if item is None:
            break
        items.append(item)
        if isinstance(item, PassThrough) and source.read < first_curve_line:
            assert source.read == len(items)  # the line yielded is the last line read
    assert [type(i).__name__ for i in items].count("CurveBlock") == 1
    assert "".join(i.text for i in items if isinstance(i, PassThrough)) == "".join(
        head + filler + filler + tail)
