"""Measure where NurbsCurve evaluation stays accurate: the numbers behind the input envelope.

    python -m tests.bench.envelope [degree|weights|range|offset|span|coords|all]

    python -m tests.bench.envelope [e2e|edges]

The first six evaluate random curves (seeded) with `NurbsCurve.derivatives` and with an exact
rational evaluation of the same float inputs (`tests.naive_nurbs.exact_evaluate`), and print the
worst errors relative to the curve's own scale: C against the largest |control point|, C' and
C'' against the largest exact |C'| and |C''| on the curve. `e2e` and `edges` convert curves at
and beyond each limit with `nurbsfeed convert` and verify them with `nurbsfeed check`.
"""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Iterator
from fractions import Fraction
from pathlib import Path

import numpy as np

from nurbsfeed.geometry import NurbsCurve, nurbs
from tests.naive_nurbs import exact_evaluate


@contextlib.contextmanager
def beyond_the_envelope() -> Iterator[None]:
    """NurbsCurve.build without the envelope's limits, to measure beyond them (in this process
    only: `e2e` and `edges` show the refusals beyond)."""
    saved = {name: getattr(nurbs, name) for name in LIMITS}
    try:
        for name in LIMITS:
            setattr(nurbs, name, LIMITS[name])
        yield
    finally:
        for name, value in saved.items():
            setattr(nurbs, name, value)


LIMITS = {"MAX_DEGREE": 10**6, "MAX_WEIGHT_RATIO": math.inf, "MIN_SPAN_REL": 0.0,
          "MAX_COORDINATE": math.inf}


def random_fields(rng: np.random.Generator, degree: int, n_ctrl: int | None = None):
    """(knots on [0, 1], points in [-1, 1]^3, weights 1): a random clamped curve."""
    n = n_ctrl if n_ctrl is not None else degree + 1 + int(rng.integers(0, 6))
    interior = np.sort(rng.uniform(0.05, 0.95, n - degree - 1))
    knots = np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
    return knots, rng.uniform(-1.0, 1.0, (n, 3)), np.ones(n)


def errors(degree: int, knots, points, weights, n_u: int, rng: np.random.Generator
           ) -> tuple[float, float, float]:
    """Worst relative errors of C, C', C'' over n_u parameters (ends and knots included).

    Ours at the stored (unit) u against the exact curve of the input at the same point of the
    input's range, u_origin + u_scale * u exactly; our derivatives scaled back to the input's u.
    """
    with beyond_the_envelope():
        curve = NurbsCurve.build(degree, knots, points, weights)
    unit = np.unique(np.concatenate([[0.0, 1.0], rng.uniform(0.0, 1.0, n_u), curve.span_breaks]))
    ours = np.stack(curve.derivatives(unit), axis=1)  # (N, 3, 3)
    ours[:, 1] /= curve.u_scale
    ours[:, 2] /= curve.u_scale ** 2
    origin, scale = Fraction(curve.u_origin), Fraction(curve.u_scale)
    exact = np.stack([exact_evaluate(degree, knots, points, weights,
                                     origin + scale * Fraction(float(x))) for x in unit])
    scales = [np.max(np.abs(points)), np.max(np.linalg.norm(exact[:, 1], axis=1)),
              np.max(np.linalg.norm(exact[:, 2], axis=1))]
    out = []
    for order in range(3):
        err = np.max(np.linalg.norm(ours[:, order] - exact[:, order], axis=1))
        out.append(err / scales[order] if scales[order] > 0 else err)
    return out[0], out[1], out[2]


def worst(cases, trials: int = 6, n_u: int = 12, seed: int = 11):
    rng = np.random.default_rng(seed)
    result = np.zeros(3)
    for _ in range(trials):
        result = np.maximum(result, errors(*cases(rng), n_u=n_u, rng=rng))
    return result


def row(label: str, values) -> None:
    e0, e1, e2 = values
    print(f"{label:>24}  C {e0:9.1e}   C' {e1:9.1e}   C'' {e2:9.1e}", flush=True)


def degree_sweep() -> None:
    print("degree (knots [0,1], |P| <= 1, weights 1, up to 5 interior knots)")
    for degree in (1, 2, 3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23, 25):
        row(f"degree {degree}",
            worst(lambda rng, degree=degree: (degree, *random_fields(rng, degree))))
    print("degree, LinuxCNC uniform integer knots (G6.2 P / G5.2 L), 2 * order control points")
    from nurbsfeed.gcode.linuxcnc import uniform_knots
    for degree in (3, 5, 7, 9, 11, 13, 15, 17, 19, 21, 23):
        def case(rng, degree=degree):
            n = 2 * (degree + 1)
            return (degree, uniform_knots(n, degree + 1), rng.uniform(0.0, 10.0, (n, 3)),
                    np.ones(n))
        row(f"degree {degree}", worst(case))


def weight_sweep() -> None:
    print("weight ratio max(w)/min(w) (degree 3 and 5, one random control point heavy)")
    for degree in (3, 5):
        for ratio in (1e2, 1e4, 1e6, 1e8, 1e10, 1e12):
            def case(rng, degree=degree, ratio=ratio):
                knots, pts, w = random_fields(rng, degree)
                w[int(rng.integers(1, len(w) - 1))] = ratio
                return degree, knots, pts, w
            row(f"p{degree} ratio {ratio:.0e}", worst(case))
            def light(rng, degree=degree, ratio=ratio):
                knots, pts, w = random_fields(rng, degree)
                w[int(rng.integers(1, len(w) - 1))] = 1.0 / ratio
                return degree, knots, pts, w
            row(f"p{degree} ratio 1/{ratio:.0e}", worst(light))


def range_sweep() -> None:
    print("knot range (knots [0, R], degree 3 and 7)")
    for degree in (3, 7):
        for rng_width in (1e-200, 1e-100, 1e-12, 1e-6, 1.0, 1e6, 1e12, 1e100, 1e150):
            def case(rng, degree=degree, width=rng_width):
                knots, pts, w = random_fields(rng, degree)
                return degree, knots * width, pts, w
            try:
                row(f"p{degree} R {rng_width:.0e}", worst(case))
            except Exception as exc:  # noqa: BLE001 - a measurement reports what happens
                print(f"{f'p{degree} R {rng_width:.0e}':>24}  {type(exc).__name__}: {exc}")


def offset_sweep() -> None:
    print("knot offset (knots [O, O + 1], degree 3 and 7)")
    for degree in (3, 7):
        for offset in (1.0, 1e3, 1e6, 1e8, 1e10, 1e12):
            def case(rng, degree=degree, offset=offset):
                knots, pts, w = random_fields(rng, degree)
                return degree, offset + knots, pts, w
            row(f"p{degree} O {offset:.0e}", worst(case))


def span_sweep() -> None:
    print("smallest span / knot range (one interior span of width h, degree 3 and 7)")
    for degree in (3, 7):
        for h in (1e-3, 1e-6, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14):
            def case(rng, degree=degree, h=h):
                knots, pts, w = random_fields(rng, degree, degree + 5)
                mid = degree + 2
                knots[mid + 1] = knots[mid] + h
                knots[mid + 1:-degree - 1] = np.maximum(knots[mid + 1:-degree - 1],
                                                        knots[mid] + h)
                return degree, np.sort(knots), pts, w
            row(f"p{degree} h {h:.0e}", worst(case, n_u=6))


def coordinate_sweep() -> None:
    print("coordinates: a curve of size 10 at offset X (absolute error, program units)")
    for degree in (3, 7):
        for offset in (0.0, 1e3, 1e6, 1e8, 1e10, 1e14):
            def case(rng, degree=degree, offset=offset):
                knots, pts, w = random_fields(rng, degree)
                return degree, knots, offset + 10.0 * pts, w
            e0, e1, e2 = worst(case)
            scale = max(offset, 10.0)
            print(f"{f'p{degree} X {offset:.0e}':>24}  |dC| {e0 * scale:9.1e}  "
                  f"(ulp {np.spacing(scale):8.1e})   C' {e1:9.1e}   C'' {e2:9.1e}", flush=True)


NURBSFEED = str(Path(sys.executable).with_name("nurbsfeed"))


def convert_and_check(curve: dict, label: str, timeout_s: float = 120.0) -> None:
    """`nurbsfeed convert` then `nurbsfeed check` on one JSON curve; one line of results."""
    import json
    import subprocess
    import tempfile
    import time
    with tempfile.TemporaryDirectory() as tmp:
        src, out = Path(tmp) / "c.json", Path(tmp) / "c.nc"
        src.write_text(json.dumps({"curves": [curve]}))
        start = time.perf_counter()
        try:
            done = subprocess.run([NURBSFEED, "convert", str(src), "-o", str(out), "-q"],
                                  capture_output=True, text=True, timeout=timeout_s)
        except subprocess.TimeoutExpired:
            print(f"{label:>24}  convert: no end after {timeout_s:g} s", flush=True)
            return
        took_s = time.perf_counter() - start
        if done.returncode != 0:
            print(f"{label:>24}  convert exit {done.returncode}: "
                  f"{(done.stderr.strip().splitlines() or [''])[-1][:90]}", flush=True)
            return
        checked = subprocess.run([NURBSFEED, "check", str(src), str(out), "--json"],
                                 capture_output=True, text=True, timeout=timeout_s)
        try:
            report = json.loads(checked.stdout)
        except ValueError:
            print(f"{label:>24}  check exit {checked.returncode}: "
                  f"{(checked.stderr.strip().splitlines() or [''])[-1][:90]}", flush=True)
            return
        worst = {c["name"]: c for c in report["checks"]}
        ratios = max(c["ratio"] for c in report["checks"])
        print(f"{label:>24}  {took_s:5.1f} s  check {'ok' if report['ok'] else 'BROKEN'}  "
              f"moves {report['moves']:6d}  path dev {worst['path-deviation']['worst']:8.1e}  "
              f"feed {worst['feed']['ratio']:.4f}  worst ratio {ratios:.3f}", flush=True)


def e2e_sweep() -> None:
    """Conversions at and beyond the candidate limits (curves ~ 20 mm, F3000)."""
    rng = np.random.default_rng(5)

    def curve(degree, knots, pts, w):
        return {"degree": int(degree), "knots": list(map(float, knots)),
                "control_points": np.asarray(pts, float).tolist(),
                "weights": list(map(float, w)), "feed": 3000}

    print("degree")
    for degree in (3, 5, 7, 9, 11, 13, 15, 19, 21):
        knots, pts, w = random_fields(rng, degree)
        convert_and_check(curve(degree, knots, 10 * pts, w), f"degree {degree}")
    print("weight ratio (one interior weight)")
    for ratio in (1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9):
        for heavy in (ratio, 1.0 / ratio):
            knots, pts, w = random_fields(rng, 3, 8)
            w[4] = heavy
            convert_and_check(curve(3, knots, 10 * pts, w), f"w[4] = {heavy:.0e}")
    print("knot range and offset")
    for lo, width in ((0.0, 1e-12), (0.0, 1e-6), (0.0, 1e6), (0.0, 1e12), (1e6, 1.0),
                      (1e9, 1.0), (1e12, 1.0)):
        knots, pts, w = random_fields(rng, 3, 8)
        convert_and_check(curve(3, lo + width * knots, 10 * pts, w),
                          f"knots [{lo:.0e}, +{width:.0e}]")
    print("smallest span / knot range")
    for h in (1e-6, 1e-8, 1e-9, 1e-10, 1e-12, 1e-14, 1e-16):
        knots, pts, w = random_fields(rng, 3, 8)
        knots[5] = knots[4] + h
        convert_and_check(curve(3, np.sort(knots), 10 * pts, w), f"span {h:.0e}")
    print("coordinates (curve ~20 mm at offset X)")
    for offset in (1e3, 1e6, 1e7, 1e8, 1e9, 1e12):
        knots, pts, w = random_fields(rng, 3, 8)
        convert_and_check(curve(3, knots, offset + 10 * pts, w), f"X {offset:.0e}")


def edge_sweep() -> None:
    """Many seeds at the candidate limits: degree 9 with a tiny span, heavy weights."""
    def curve(degree, knots, pts, w):
        return {"degree": int(degree), "knots": list(map(float, knots)),
                "control_points": np.asarray(pts, float).tolist(),
                "weights": list(map(float, w)), "feed": 3000}

    print("degree 9, narrowest span 1e-12 of the range, weights 0.5 .. 2")
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        knots, pts, w = random_fields(rng, 9, 14)
        knots[11] = knots[10] + 1e-12
        w = rng.uniform(0.5, 2.0, len(w))
        convert_and_check(curve(9, np.sort(knots), 10 * pts, w), f"p9 seed {seed}")
    print("heavy interior weights (degree 2, 3, 5; one or two heavy control points)")
    for ratio in (1e3, 3e3, 1e4, 3e4, 1e5):
        for seed in range(8):
            rng = np.random.default_rng(200 + seed)
            degree = (2, 3, 5)[seed % 3]
            knots, pts, w = random_fields(rng, degree, degree + 6)
            w[rng.choice(np.arange(1, len(w) - 1), 1 + seed % 2, replace=False)] = ratio
            convert_and_check(curve(degree, knots, 10 * pts, w),
                              f"p{degree} ratio {ratio:.0e} s{seed}")


EVALUATION = {"degree": degree_sweep, "weights": weight_sweep, "range": range_sweep,
              "offset": offset_sweep, "span": span_sweep, "coords": coordinate_sweep}
SWEEPS = EVALUATION | {"e2e": e2e_sweep, "edges": edge_sweep}

if __name__ == "__main__":
    names = sys.argv[1:] or ["all"]
    for name in EVALUATION if names == ["all"] else names:
        SWEEPS[name]()
