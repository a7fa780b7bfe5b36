"""S-curve closed forms (Eq. 17-20 with errata) as properties, integrated independently."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nurbsfeed.planning.scurve import (
    peak_speed,
    reachable_speed,
    scan_speeds,
    transition_distance_mm,
    transition_phases,
    transition_time_s,
)
from tests.conftest import law_at, law_from_segments, law_increments, law_speed_at_arc

speeds = st.floats(0.0, 500.0)
accs = st.floats(1.0, 1e4)
jerks = st.floats(10.0, 1e6)
lengths = st.floats(1e-6, 1e3)


def integrate(v0: float, phases: list[tuple[float, float]]) -> tuple[float, float, float, float,
                                                                       float]:
    """Exact integration of constant-jerk phases from (v0, a=0): s, v, a, max|a|, duration."""
    s, v, a, amax, t = 0.0, v0, 0.0, 0.0, 0.0
    for dur, j in phases:
        s += v * dur + a * dur**2 / 2 + j * dur**3 / 6
        v += a * dur + j * dur**2 / 2
        a += j * dur
        amax = max(amax, abs(a))
        t += dur
    return s, v, a, amax, t


@settings(max_examples=400, deadline=None)
@given(speeds, speeds, accs, jerks)
def test_transition_reaches_its_speed_within_limits_and_its_distance_is_the_mean(v0, v1, acc,
                                                                                jerk) -> None:
    durations, jerks = np.empty(3), np.empty(3)
    n = transition_phases(v0, v1, acc, jerk, durations, jerks)
    phases = list(zip(durations[:n], jerks[:n]))
    s, v, a, amax, t = integrate(v0, phases)
    scale = max(v0, v1, 1.0)
    assert v == pytest.approx(v1, abs=1e-9 * scale)
    assert a == pytest.approx(0.0, abs=1e-9 * acc)
    assert amax <= acc * (1 + 1e-12)
    assert all(abs(j) <= jerk for _, j in phases)
    assert t == pytest.approx(float(transition_time_s(v1 - v0, acc, jerk)), rel=1e-12, abs=1e-15)
    assert s == pytest.approx(float(transition_distance_mm(v0, v1, acc, jerk)), rel=1e-9,
                              abs=1e-12)


def test_transition_time_branches_of_eq_17() -> None:
    # Table 1: A = 1000, J = 1e4, so A^2/J = 100 mm/s separates the branches.
    assert transition_time_s(100.0, 1000.0, 1e4) == pytest.approx(0.2)  # 2 sqrt(100/1e4)
    assert transition_time_s(25.0, 1000.0, 1e4) == pytest.approx(0.1)  # 2 sqrt(25/1e4)
    assert transition_time_s(300.0, 1000.0, 1e4) == pytest.approx(0.4)  # 300/1000 + 0.1
    assert transition_distance_mm(0.0, 100.0, 1000.0, 1e4) == pytest.approx(10.0)


@settings(max_examples=400, deadline=None)
@given(speeds, lengths, accs, jerks, speeds)
def test_reachable_speed_is_the_highest_that_fits(v0, length, acc, jerk, extra) -> None:
    cap = v0 + extra
    v = reachable_speed(v0, length, acc, jerk, cap)
    assert v0 <= v <= cap
    assert transition_distance_mm(v0, v, acc, jerk) <= length
    if v < cap:  # not capped: the length is used up (up to the bisection precision)
        slightly_more = v * (1 + 1e-9) + 1e-12
        assert transition_distance_mm(v0, slightly_more, acc, jerk) > length * (1 - 1e-9)


@settings(max_examples=300, deadline=None)
@given(speeds, speeds, lengths, accs, jerks, st.floats(0.0, 500.0))
def test_peak_speed_fits_the_segment_and_cannot_be_raised(va, vb, length, acc, jerk,
                                                          cap_extra) -> None:
    need = float(transition_distance_mm(va, vb, acc, jerk))
    length = max(length, need)  # the scan guarantees the ends are reachable
    cap = max(va, vb) + cap_extra
    vp = peak_speed(va, vb, length, cap, acc, jerk)
    used = float(transition_distance_mm(va, vp, acc, jerk) + transition_distance_mm(vp, vb,
                                                                                   acc, jerk))
    assert max(va, vb) <= vp <= cap
    assert used <= length
    if vp < cap:
        more = vp * (1 + 1e-9) + 1e-12
        assert (transition_distance_mm(va, more, acc, jerk)
                + transition_distance_mm(more, vb, acc, jerk)) > length * (1 - 1e-9)


def test_time_law_is_continuous_and_respects_the_tangential_limits() -> None:
    rng = np.random.default_rng(3)
    acc, jerk = 1000.0, 1e4
    s_key = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5, 40.0, 12))])
    v_key = np.concatenate([[0.0], rng.uniform(5, 90, 11), [0.0]])
    length = np.diff(s_key)
    cap = np.full(len(length), 100.0)
    v_key = scan_speeds(v_key, length, cap, acc, jerk)
    for i in range(len(length)):  # the scan's guarantee: every segment's ends are reachable
        assert transition_distance_mm(v_key[i], v_key[i + 1], acc, jerk) <= length[i]
    holds = np.zeros(len(length))
    peak = np.array([peak_speed(v_key[i], v_key[i + 1], length[i], 100.0, acc, jerk)
                     for i in range(len(length))])
    law = law_from_segments(s_key, v_key, peak, holds, holds, acc, jerk)
    t = np.linspace(0.0, law.duration_s, 20001)
    s, v, a, j = law_at(law, t)
    assert s[0] == 0.0 and s[-1] == pytest.approx(s_key[-1], abs=1e-9)
    assert np.all(np.diff(s) >= -1e-12)
    assert np.max(np.abs(a)) <= acc * (1 + 1e-9) and np.max(np.abs(j)) <= jerk
    assert np.max(v) <= 100.0 * (1 + 1e-12)
    # continuity of s, v, a at every piece start (evaluate just before and at the boundary)
    inner = law.t0_s[1:]
    before = law_at(law, inner - 1e-12)
    after = law_at(law, inner)
    for k in range(3):
        assert np.allclose(before[k], after[k], atol=1e-6)
    # the law passes every key point at its planned speed
    t_key = np.interp(s_key, s, t)
    assert np.allclose(law_at(law, t_key)[1], v_key, atol=1e-3)
    # increments agree with differences of s
    inc = law_increments(law, t)
    assert np.allclose(inc, np.diff(s), atol=1e-9)
    assert np.allclose(law_speed_at_arc(law, s[1:-1]), v[1:-1], atol=1e-6)
    # in any order (binary search instead of the forward pointer): the same speeds
    shuffled = np.random.default_rng(4).permutation(s.size - 2) + 1
    assert np.allclose(law_speed_at_arc(law, s[shuffled]), v[shuffled], atol=1e-6)
    assert np.allclose(law_at(law, t[shuffled])[1], v[shuffled], atol=1e-12)


def test_speed_at_arc_skips_only_pieces_that_cannot_exceed_the_floor() -> None:
    """What the planner checks: v at a node is worked out only where the law's piece can be
    faster than the node's limit (its speeds at both ends and any turning point bound it)."""
    acc, jerk = 1000.0, 1e4
    s_key = np.array([0.0, 30.0, 45.0, 80.0])
    v_key = np.array([0.0, 60.0, 35.0, 0.0])
    length = np.diff(s_key)
    peak = np.array([peak_speed(v_key[i], v_key[i + 1], length[i], 100.0, acc, jerk)
                     for i in range(3)])
    law = law_from_segments(s_key, v_key, peak, np.zeros(3), np.zeros(3), acc, jerk)
    s = np.linspace(0.0, s_key[-1], 4001)
    full = law_speed_at_arc(law, s)
    floor = np.random.default_rng(5).uniform(0.0, 100.0, s.size)
    out = law_speed_at_arc(law, s, floor)
    solved = out > 0.0
    assert np.allclose(out[solved], full[solved], rtol=1e-10, atol=0.0)  # Newton to 1e-12
    assert np.all(full[~solved] <= floor[~solved] * (1 + 1e-12))  # skipped: cannot exceed
    assert np.all(solved[full > floor])
