"""G1 output rules (design §5): decimal points, no -0., no zero moves, F from the written
coordinates."""

from __future__ import annotations

import io
import math
import re

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from nurbsfeed.gcode.writer import MoveWriter, format_number, round_ticks, run_start
from tests.gcode_parse import moves


@pytest.mark.parametrize(("value", "decimals", "text"), [
    (50.0, 4, "50."), (0.0, 4, "0."), (12.34, 4, "12.34"), (-3.5, 4, "-3.5"),
    (0.0001, 4, "0.0001"), (-0.00004, 4, "0."), (-0.00005, 4, "-0.0001"), (0.00005, 4, "0.0001"),
    (123456.78915, 4, "123456.7892"), (-0.1, 1, "-0.1"), (7.0, 0, "7."), (1e-9, 4, "0."),
    (99.99995, 4, "100."), (2.5, 5, "2.5"),
    # every digit count and grouping: fractions of 1..8 digits, long integer parts
    (1234567890123.0, 0, "1234567890123."), (-98765.4321, 4, "-98765.4321"),
    (0.000123, 6, "0.000123"), (1.5, 9, "1.5"), (12345678.9, 1, "12345678.9"),
    (-7.0000001, 7, "-7.0000001"), (100000.0, 8, "100000."),
    (987654321.987654, 6, "987654321.987654"),
])
def test_number_format_always_has_a_point_and_never_a_negative_zero(value, decimals,
                                                                   text) -> None:
    assert written_x(value, decimals) == text
    assert format_number(value, decimals) == text


def written_x(value: float, decimals: int) -> str:
    """The X word the hot loop writes for a move to X = value (from one unit further on)."""
    text, _ = write(np.array([[value + 1.0, 0.0, 0.0], [value, 0.0, 0.0]]), decimals)
    return text.split()[1].removeprefix("X")


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e6, 1e6, allow_nan=False), st.integers(0, 8))
def test_format_number_writes_what_the_hot_loop_writes(value: float, decimals: int) -> None:
    assume(round(value * 10.0**decimals) != round((value + 1.0) * 10.0**decimals))
    assert format_number(value, decimals) == written_x(value, decimals)


def test_format_number_writes_any_finite_value() -> None:
    assert format_number(1e20, 0) == "100000000000000000000."
    assert (format_number(2.5, 0), format_number(-0.5, 0)) == ("3.", "-1.")  # half away from 0
    assert format_number(-4e-7, 6) == "0."


def test_decimals_beyond_int64_ticks_are_refused() -> None:
    with pytest.raises(ValueError):
        MoveWriter(io.BytesIO(), 19, 3, 0.001, "\n", np.zeros(3))


def write(points: np.ndarray, decimals: int = 4, period_s: float = 0.001,
          eol: str = "\n") -> tuple[str, MoveWriter]:
    out = io.BytesIO()
    writer = MoveWriter(out, decimals, 3, period_s, eol, points[0])
    writer.write(points[1:])
    return out.getvalue().decode("ascii"), writer


def slow_start_path(n: int = 3000) -> np.ndarray:
    """A path that starts and ends at rest: sub-resolution steps at both ends, 3-D."""
    t = np.linspace(0.0, 1.0, n)
    s = 3 * t**2 - 2 * t**3  # smoothstep: zero speed at both ends
    return np.column_stack([20 * s - 5, 7 * np.sin(3 * s), -0.3 * s])


def test_every_move_lasts_its_periods_according_to_its_written_coordinates() -> None:
    pts = slow_start_path()
    text, writer = write(pts)
    written, feeds, raw = moves(text, round_ticks(pts[:1], 4)[0] / 1e4)
    # recover n for every move: the index of each written point among the rounded inputs
    ticks = round_ticks(pts, 4)
    keep = np.flatnonzero(np.any(np.diff(ticks, axis=0) != 0, axis=1)) + 1
    periods = np.diff(np.concatenate([[0], keep]))
    assert len(written) == len(keep) == writer.moves
    step = np.linalg.norm(np.diff(np.vstack([ticks[:1] / 1e4, written]), axis=0), axis=1)
    duration = step / (feeds / 60.0)
    assert np.allclose(duration, periods * 0.001, rtol=5e-4)
    assert periods.max() > 1 and np.median(periods) == 1  # merged only near standstill
    assert np.allclose(written, ticks[keep] / 1e4, atol=1e-12)
    assert np.allclose(written[-1], pts[-1], atol=0.5e-4)


def test_no_zero_length_move_no_f0_no_negative_zero_and_a_point_on_every_number() -> None:
    text, _ = write(slow_start_path())
    written, feeds, raw = moves(text, slow_start_path()[0])
    assert np.all(np.linalg.norm(np.diff(written, axis=0), axis=1) > 0)
    assert np.all(feeds > 0)
    numbers = re.findall(r"[XYZF](-?[\d.]+)", text)
    assert numbers and all("." in n for n in numbers)
    assert not re.search(r"-0\.0*(\s|$)", text)
    assert not re.search(r"F0?\.0*(\s|$)", text)
    assert raw[0].startswith("G1 ") and not any(r.startswith("G1") for r in raw[1:])


def test_modal_words_are_not_repeated() -> None:
    pts = np.column_stack([np.arange(5.0), np.zeros(5), np.full(5, 2.0)])
    text, _ = write(pts)
    assert text.splitlines() == ["G1 X1. F60000.", "X2.", "X3.", "X4."]


def test_line_endings_follow_the_program() -> None:
    pts = np.column_stack([np.arange(3.0), np.zeros(3), np.zeros(3)])
    text, _ = write(pts, eol="\r\n")
    assert text == "G1 X1. F60000.\r\nX2.\r\n"


def test_tiny_feeds_keep_five_significant_digits() -> None:
    # 0.0001 mm over 7 periods of 1 ms: F = 60 * 0.0001 / 0.007 = 0.857142857... mm/min
    pts = np.zeros((8, 3))
    pts[7, 0] = 0.0001
    text, _ = write(pts)
    assert text == "G1 X0.0001 F0.85714\n"


def test_chunked_writing_equals_one_shot_writing() -> None:
    pts = slow_start_path(200_000)
    whole, _ = write(pts)
    out = io.BytesIO()
    writer = MoveWriter(out, 4, 3, 0.001, "\n", pts[0])
    for lo in range(1, len(pts), 7919):
        writer.write(pts[lo:lo + 7919])
    assert out.getvalue().decode() == whole


def reference_moves(points: np.ndarray, start: np.ndarray, decimals: int, feed_decimals: int,
                    period_s: float, eol: str) -> str:
    """design §5 written out plainly, one point at a time, with Python's own formatting."""
    def ticks(x: float) -> int:
        scaled = x * 10.0**decimals
        return int(math.copysign(math.floor(abs(scaled) + 0.5), scaled))

    def text(value: int, digits: int) -> str:
        whole, frac = divmod(abs(value), 10**digits)
        fraction = f"{frac:0{digits}d}".rstrip("0") if digits else ""
        return f"{'-' if value < 0 else ''}{whole}.{fraction}"

    last, pending, last_feed, lines = [ticks(v) for v in start], 0, None, []
    for point in points:
        now = [ticks(v) for v in point]
        pending += 1
        if now == last:
            continue
        dist = math.sqrt(sum(float(a - b) ** 2 for a, b in zip(now, last))) * 10.0**-decimals
        feed = 60.0 * dist / (pending * period_s)
        feed_dec = int(min(max(4 - math.floor(math.log10(feed)), feed_decimals), 6))
        feed_text = text(math.floor(feed * 10.0**feed_dec + 0.5), feed_dec)
        words = [f"{axis}{text(v, decimals)}" for axis, v, was in zip("XYZ", now, last)
                 if v != was]
        if feed_text != last_feed:
            words.append("F" + feed_text)
            last_feed = feed_text
        lines.append(("" if lines else "G1 ") + " ".join(words) + eol)
        last, pending = now, 0
    return "".join(lines)


@pytest.mark.parametrize("seed, decimals, feed_decimals, period_s, eol", [
    (0, 4, 3, 0.001, "\n"), (1, 3, 2, 0.0005, "\r\n"), (2, 5, 3, 0.002, "\n"),
    (3, 0, 0, 0.001, "\n"), (4, 4, 6, 0.004, "\n")])
def test_moves_match_a_plain_reference_writer(seed, decimals, feed_decimals, period_s,
                                             eol) -> None:
    rng = np.random.default_rng(seed)
    slow = slow_start_path(2000) * rng.uniform(0.1, 50.0)
    jumps = rng.normal(0.0, 30.0, (300, 3))  # sign changes, values near 0, big moves
    creep = np.cumsum(rng.normal(0.0, 10.0**-decimals, (500, 3)), axis=0)
    points = np.vstack([slow, jumps, creep])
    out = io.BytesIO()
    writer = MoveWriter(out, decimals, feed_decimals, period_s, eol, points[0])
    for lo in range(1, len(points), 997):
        writer.write(points[lo:lo + 997])
    expected = reference_moves(points[1:], points[0], decimals, feed_decimals, period_s, eol)
    assert out.getvalue().decode("ascii") == expected


def test_the_move_onto_the_end_spans_every_period_up_to_the_end() -> None:
    """The last points of a curve round onto its end: they are held at the point before them,
    so the final move lasts all their periods and the moves cover the whole planned time."""
    pts = slow_start_path(30000)
    ticks = round_ticks(pts, 4)
    same_as_end = np.all(ticks == ticks[-1], axis=1)
    assert same_as_end[-5:].all()  # the path really ends at rest, below the resolution
    first_same = int(np.flatnonzero(~same_as_end)[-1]) + 1
    assert run_start(pts, ticks[-1], 4) == first_same
    out = io.BytesIO()
    MoveWriter(out, 4, 3, 0.001, "\n", pts[0]).write_curve(pts)
    text = out.getvalue().decode("ascii")
    written, feeds, _ = moves(text, ticks[0] / 1e4)
    step = np.linalg.norm(np.diff(np.vstack([ticks[:1] / 1e4, written]), axis=0), axis=1)
    periods = np.round(step / (feeds / 60.0) / 0.001)
    assert periods.sum() == len(pts) - 1
    assert np.array_equal(written[-1], ticks[-1] / 1e4)
    # the same text as the points with the trailing run replaced by the point before it
    held = pts.copy()
    held[first_same:-1] = pts[first_same - 1]
    assert text == write(held)[0]
    assert write(pts)[0] != text  # written as they are, the run would arrive early


def test_a_short_curve_holds_its_end_run_too() -> None:
    """Fewer points than the writer first looks at (16): the run onto the end is still found
    (here points 6 and 7 round onto the end), so the last move spans its three periods."""
    pts = np.array([[0.0, 0.0], [0.6, 0.3], [4.7, 2.2], [15.2, 5.7], [30.0, 7.5], [44.8, 5.7],
                    [55.3, 2.2], [59.4, 0.3], [60.0, 0.0]]) * 1e-5  # a 0.6 um curve, at rest
    pts = np.column_stack([pts, np.zeros(9)])
    ticks = round_ticks(pts, 4)
    assert np.array_equal(ticks[5:], [[4, 1, 0], [6, 0, 0], [6, 0, 0], [6, 0, 0]])
    assert run_start(pts, ticks[-1], 4) == 6
    out = io.BytesIO()
    MoveWriter(out, 4, 3, 0.001, "\n", pts[0]).write_curve(pts)
    written, feeds, _ = moves(out.getvalue().decode("ascii"), ticks[0] / 1e4)
    step = np.linalg.norm(np.diff(np.vstack([ticks[:1] / 1e4, written]), axis=0), axis=1)
    periods = np.round(step / (feeds / 60.0) / 0.001)
    assert periods.sum() == len(pts) - 1 and periods[-1] == 3


def test_a_curve_with_no_point_rounding_onto_its_end_is_written_as_it_is() -> None:
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.5, 0.0], [3.0, 1.0, 0.0]])
    assert run_start(pts, round_ticks(pts[-1:], 4)[0], 4) == len(pts) - 1
    out = io.BytesIO()
    MoveWriter(out, 4, 3, 0.001, "\n", pts[0]).write_curve(pts)
    assert out.getvalue().decode("ascii") == write(pts)[0]
    # all of them round onto the end: nothing is held, nothing moves
    still = np.full((5, 3), 1.00001)
    assert run_start(still, round_ticks(still[-1:], 4)[0], 4) == 0
    out = io.BytesIO()
    writer = MoveWriter(out, 4, 3, 0.001, "\n", still[0])
    writer.write_curve(still)
    assert out.getvalue() == b"" and writer.moves == 0




def test_a_curve_written_in_chunks_of_any_size_is_the_curve_written_whole() -> None:
    """The run onto the end is held across chunk boundaries (a conversion hands the writer a
    curve in chunks), and a run that rounds onto the last point of a chunk but is left again
    by the next one is written as it would have been."""
    rng = np.random.default_rng(7)
    ends_at_rest = slow_start_path(3000)
    back = slow_start_path(600)[::-1]  # reaches its end, stays there below the resolution,
    away = np.vstack([back, back[-1] + np.cumsum(rng.normal(0, 1e-3, (50, 3)), axis=0),
                      back[::-1], back])  # leaves, comes back, rests, leaves, ends at rest
    for pts in (ends_at_rest, away):
        whole = io.BytesIO()
        MoveWriter(whole, 4, 3, 0.001, "\n", pts[0]).write_curve(pts)
        for size in (1, 2, 7, 16, 100, 1000):
            out = io.BytesIO()
            writer = MoveWriter(out, 4, 3, 0.001, "\n", pts[0])
            for lo in range(1, len(pts), size):
                writer.add_points(pts[lo:lo + size])
            writer.end_curve()
            assert out.getvalue() == whole.getvalue(), size
        written, _, _ = moves(whole.getvalue().decode("ascii"), round_ticks(pts[:1], 4)[0] / 1e4)
        assert np.array_equal(written[-1], round_ticks(pts[-1:], 4)[0] / 1e4)
