#!/usr/bin/env python3
"""tools/tolerance_report.py CASES.csv...: the tables of issue 29 §3 from tools/tolerance-check
(several files are read as one: a sweep from one run, tolerance cases from another).

1. Per method: cases that met E, misses reported (`met` false) or silent, cases not
   over-accurate (measured >= E/10), and the adaptive integrator's own estimate against the
   measured error.
2. With the fixed-step sweep (ORACLE=1): per scene, the oracle is the fixed step chosen with
   hindsight: the error of the sweep's worst view, interpolated log-log between steps, gives
   the step that reaches a target error, and its evaluations and GPU time are interpolated the
   same way (means over the views). Printed: the adaptive integrator's evaluations against the
   oracle's at the adaptive frames' error (worst view), and the time to meet E with the
   tolerance (frame GPU time; the pilots' wall time beside it) against the oracle's time at E.
3. One step for all scenes: for each swept step, on which scenes it misses E and its cost
   against each scene's oracle at E.
"""
import csv
import math
import sys
from collections import defaultdict


def f(x):
    return float(x) if x not in ("", None) else None


def interp(points, target):
    """points: (step, error, value) sorted by decreasing step. The value at the largest step
    whose interpolated error reaches `target` (log-log between neighbours); None when no step
    of the sweep reaches it."""
    for (s0, e0, v0), (s1, e1, v1) in zip(points, points[1:]):
        if e0 <= target:
            return v0, s0
        if e1 <= target:
            if e0 <= 0 or e1 <= 0 or e0 == e1:
                return v1, s1
            u = (math.log(target) - math.log(e0)) / (math.log(e1) - math.log(e0))
            s = math.exp(math.log(s0) + u * (math.log(s1) - math.log(s0)))
            v = math.exp(math.log(v0) + u * (math.log(v1) - math.log(v0)))
            return v, s
    if points and points[-1][1] <= target:
        return points[-1][2], points[-1][0]
    return None, None


def main(paths):
    rows = [r for p in paths for r in csv.DictReader(open(p))]
    cases = [r for r in rows if r["method"] in ("fixed", "adaptive")]
    print("## Tolerance kept")
    for method in ("fixed", "adaptive"):
        r = [x for x in cases if x["method"] == method]
        if not r:
            continue
        met = sum(f(x["measured"]) <= f(x["requested"]) for x in r)
        tight = sum(f(x["measured"]) >= f(x["requested"]) / 10 for x in r)
        said = sum(f(x["measured"]) > f(x["requested"]) and x["met"] == "false" for x in r)
        silent = sum(f(x["measured"]) > f(x["requested"]) and x["met"] == "true" for x in r)
        print(f"{method}: {met} of {len(r)} cases met E ({said} misses reported as not met, "
              f"{silent} silent); {tight} of {len(r)} measured at least E/10")
        est = [x for x in r if f(x.get("error_estimate"))]
        if est:
            above = sum(f(x["error_estimate"]) >= f(x["measured"]) for x in est)
            ratios = sorted(f(x["error_estimate"]) / max(f(x["measured"]), 1e-12) for x in est)
            print(f"  its own estimate (p99) >= measured in {above} of {len(est)} cases; "
                  f"estimate/measured median {ratios[len(ratios) // 2]:.1f}, "
                  f"range {ratios[0]:.1f}-{ratios[-1]:.1f}")
    sweep = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r["method"] == "sweep":
            sweep[r["scene"]][f(r["value"])].append(r)
    if not sweep:
        return
    # Per scene: (step, worst view's error, mean evaluations, mean GPU ms), steps decreasing.
    curves = {}
    for scene, by_step in sweep.items():
        pts = []
        for step in sorted(by_step, reverse=True):
            rs = by_step[step]
            pts.append((step, max(f(x["measured"]) for x in rs),
                        sum(f(x["evaluations"]) for x in rs) / len(rs),
                        sum(f(x["frame_gpu_ms"]) for x in rs) / len(rs)))
        curves[scene] = pts
    print()
    print("## Adaptive against the oracle's fixed step at equal error (worst view)")
    print(f"{'scene':<18} {'E':>7} {'adaptive p99':>12} {'adaptive evals':>14} "
          f"{'oracle step':>11} {'oracle evals':>12} {'ratio':>6} {'adaptive ms':>11} "
          f"{'oracle ms':>9}")
    for scene, pts in curves.items():
        for e in sorted({x["requested"] for x in cases if x["scene"] == scene}, key=float,
                        reverse=True):
            a = [x for x in cases if x["scene"] == scene and x["method"] == "adaptive"
                 and x["requested"] == e]
            if not a:
                continue
            err = max(f(x["measured"]) for x in a)
            evals = sum(f(x["evaluations"]) for x in a) / len(a)
            ms = sum(f(x["frame_gpu_ms"]) for x in a) / len(a)
            ev, step = interp([(s, er, v) for s, er, v, _ in pts], err)
            tm, _ = interp([(s, er, t) for s, er, _, t in pts], err)
            if ev is None:
                print(f"{scene:<18} {e:>7} {err:>12.2e} {evals:>14.0f} "
                      f"{'(none)':>11} {'-':>12} {'-':>6} {ms:>11.1f} {'-':>9}")
                continue
            print(f"{scene:<18} {e:>7} {err:>12.2e} {evals:>14.0f} {step:>11.4f} {ev:>12.0f} "
                  f"{evals / ev:>6.2f} {ms:>11.1f} {tm:>9.1f}")
    print()
    print("## One tolerance, no tuning: GPU ms to meet E (mean over views; pilots' wall s)")
    es = sorted({x["requested"] for x in cases}, key=float, reverse=True)
    oracle = {}
    for e in es:
        print(f"E = {e}")
        print(f"  {'scene':<18} {'oracle step':>11} {'oracle ms':>9} {'fixed tol ms':>12} "
              f"{'ratio':>6} {'adaptive ms':>11} {'ratio':>6} {'pilots s':>8}")
        for scene, pts in curves.items():
            tm, step = interp([(s, er, t) for s, er, _, t in pts], float(e))
            oracle[(scene, e)] = tm
            line = f"  {scene:<18} "
            line += f"{step:>11.4f} {tm:>9.1f} " if tm else f"{'(none)':>11} {'-':>9} "
            pilot = []
            for method in ("fixed", "adaptive"):
                r = [x for x in cases if x["scene"] == scene and x["method"] == method
                     and x["requested"] == e]
                if not r:
                    line += f"{'-':>12} {'-':>6} " if method == "fixed" else f"{'-':>11} {'-':>6} "
                    continue
                ms = sum(f(x["frame_gpu_ms"]) for x in r) / len(r)
                pilot += [f(x["pilot_wall_ms"]) / 1e3 for x in r]
                width = 12 if method == "fixed" else 11
                ratio = f"{ms / tm:>6.2f}" if tm else f"{'-':>6}"
                line += f"{ms:>{width}.1f} {ratio} "
            line += f"{sum(pilot) / max(len(pilot), 1):>8.1f}"
            print(line)
    print()
    print("## One step shared by all scenes (rows: step; per scene: misses E, or cost / oracle)")
    steps = sorted({s for pts in curves.values() for s, *_ in pts}, reverse=True)
    for e in es:
        print(f"E = {e}")
        for step in steps:
            cells = []
            for scene, pts in curves.items():
                p = [x for x in pts if x[0] == step]
                if not p:
                    cells.append(f"{scene}: -")
                    continue
                _, err, _, ms = p[0]
                if err > float(e):
                    cells.append(f"{scene}: misses ({err:.1e})")
                elif oracle.get((scene, e)):
                    cells.append(f"{scene}: {ms / oracle[(scene, e)]:.1f}x")
                else:
                    cells.append(f"{scene}: meets")
            print(f"  step {step:<8} " + "; ".join(cells))


if __name__ == "__main__":
    main(sys.argv[1:])
