#!/usr/bin/env python3
"""Rounds of `volcast-bench error` and `error-synthetic` brought together (docs/performance.md,
"Adaptive stepping"): per cell the median over rounds of each round's median time (errors and
samples per ray are the same in every round: no jitter), each stepping's Pareto fronts from
those medians, and where adaptive stepping reaches an error faster or in fewer samples than
uniform stepping does.

    python3 tests/bench/error_rounds.py out/adaptive/round1 out/adaptive/round2 out/adaptive/round3
    python3 tests/bench/error_rounds.py --backend=opencl out/adaptive-opencl/round1 ...

Prints Markdown; reads ROUND/error_vs_time.json and ROUND/error_synthetic.json where present.
With --backend=NAME only that back end's points (rounds run with --backends opencl,cpu hold
both; without it, fronts and comparisons are over every back end's points together).
"""

import json
import math
import statistics
import sys
from pathlib import Path


def front(points, cost):
    """Points no other point beats in both cost and error (bench.cpp's paretoFront)."""
    out = []
    for p in points:
        beaten = any(q is not p and cost(q) <= cost(p) and q["rmse"] <= p["rmse"]
                     and (cost(q) < cost(p) or q["rmse"] < p["rmse"]) for q in points)
        if not beaten:
            out.append(p)
    return out


def cost_at_error(curve, cost, target):
    """bench.cpp's costAtError: log-log interpolation between the two points bracketing target."""
    c = sorted(curve, key=cost)
    for a, b in zip(c, c[1:]):
        if a["rmse"] >= target >= b["rmse"] and min(cost(a), cost(b), a["rmse"], b["rmse"], target) > 0:
            if a["rmse"] == b["rmse"]:
                return cost(a)
            f = (math.log(target) - math.log(a["rmse"])) / (math.log(b["rmse"]) - math.log(a["rmse"]))
            return math.exp(math.log(cost(a)) + f * (math.log(cost(b)) - math.log(cost(a))))
    return float("nan")


def merge(rounds, study):
    """One point per cell: the rounds' medians, their median, min and max."""
    cells = {}
    for r in rounds:
        f = Path(r) / f"{study}.json"
        if not f.exists():
            continue
        for p in json.loads(f.read_text())["points"]:
            key = (p["scan"], p["backend"], p["configuration"], p["stepping"], p["step"])
            c = cells.setdefault(key, dict(p, ms=[]))
            if abs(c["rmse"] - p["rmse"]) > 1e-12 + 1e-9 * c["rmse"]:
                sys.exit(f"{key}: RMSE differs between rounds ({c['rmse']} and {p['rmse']})")
            c["ms"].append(p["frame_ms"]["median"])
    for c in cells.values():
        c["t"] = statistics.median(c["ms"])
    return list(cells.values())


def fmt_ms(p):
    return f"{p['t']:.1f} ({min(p['ms']):.1f}–{max(p['ms']):.1f})"


def ratios(uniform, adaptive, cost, floor_margin=1):
    """For each adaptive point: uniform's cost at its error over its own cost (> 1: adaptive cheaper)."""
    floor = min(p["rmse"] for p in uniform)
    out = []
    for p in adaptive:
        if p["rmse"] < floor_margin * floor:
            continue
        u = cost_at_error(uniform, cost, p["rmse"])
        if math.isfinite(u):
            out.append((p, u / cost(p)))
    return out


def span(values):
    if not values:
        return "—"
    return f"{min(values):.2f}–{max(values):.2f} (median {statistics.median(values):.2f})"


def scans_report(points, nrounds):
    t = lambda p: p["t"]
    s = lambda p: p["samples_per_ray"]
    print(f"Per scan, each stepping's Pareto fronts over the medians of {nrounds} rounds "
          "(★ error against time, ◆ error against samples per ray); ms: median of the rounds' medians (range):\n")
    summary = []
    for scan in dict.fromkeys(p["scan"] for p in points):
        sp = [p for p in points if p["scan"] == scan]
        by = {st: [p for p in sp if p["stepping"] == st] for st in ("uniform", "adaptive")}
        ft = {st: front(v, t) for st, v in by.items()}
        fs = {st: front(v, s) for st, v in by.items()}
        print(f"**{scan}**\n")
        print("| stepping | configuration | step | median ms (range) | RMSE | PSNR dB | samples per ray | mean step (voxels) | front |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---|")
        for st in ("uniform", "adaptive"):
            shown = [p for p in by[st] if p in ft[st] or p in fs[st]]
            for p in sorted(shown, key=t):
                mark = ("★" if p in ft[st] else "") + (" ◆" if p in fs[st] else "")
                mean = p["adaptive_mean_step_voxels"] if st == "adaptive" else p["step"]
                print(f"| {st} | {p['configuration']} {p['label']} | {p['step']:g} | {fmt_ms(p)} | {p['rmse']*1e3:.3f}e-3 | "
                      f"{p['psnr']:.1f} | {p['samples_per_ray']:.1f} | {mean:.2f} | {mark.strip()} |")
        print()
        # Adaptive's front against uniform's front at the same error.
        rt = ratios(ft["uniform"], ft["adaptive"], t)
        rs = ratios(fs["uniform"], fs["adaptive"], s)
        summary.append((scan, ft, fs, rt, rs))
    print("Adaptive's front points placed on uniform's front at the same RMSE (log–log between the two uniform "
          "points around it; > 1: adaptive reaches that error faster, or in fewer samples):\n")
    print("| scan | uniform front, time: fastest … most accurate | adaptive front, time: fastest … most accurate | "
          "uniform ÷ adaptive time (points) | uniform ÷ adaptive samples per ray (points) |")
    print("|---|---|---|---|---|")
    for scan, ft, fs, rt, rs in summary:
        ends = lambda f: (lambda a, b: f"{a['configuration']} {a['step']:g}: {a['t']:.0f} ms, {a['rmse']*1e3:.2f}e-3 … "
                                       f"{b['configuration']} {b['step']:g}: {b['t']:.0f} ms, {b['rmse']*1e3:.3f}e-3")(
            min(f, key=lambda p: p["t"]), max(f, key=lambda p: p["t"]))
        print(f"| {scan} | {ends(ft['uniform'])} | {ends(ft['adaptive'])} | {span([r for _, r in rt])} ({len(rt)}) | "
              f"{span([r for _, r in rs])} ({len(rs)}) |")
    print()
    configs = list(dict.fromkeys((p["configuration"], p["label"]) for p in points))
    print("Each configuration alone: its adaptive points placed on its own uniform curve at the same RMSE "
          "(all steps; > 1: adaptive cheaper), samples per ray and time, median over the points (range):\n")
    print("| scan | " + " | ".join(f"{k} {label}" for k, label in configs) + " |")
    print("|---|" + "---|" * len(configs))
    for scan in dict.fromkeys(p["scan"] for p in points):
        cells = []
        for key, _ in configs:
            u = [p for p in points if p["scan"] == scan and p["configuration"] == key and p["stepping"] == "uniform"]
            a = [p for p in points if p["scan"] == scan and p["configuration"] == key and p["stepping"] == "adaptive"]
            rs = [r for _, r in ratios(u, a, s)]
            rt = [r for _, r in ratios(u, a, t)]
            cells.append(f"samples {span(rs)}; time {span(rt)}" if rs else "—")
        print(f"| {scan} | " + " | ".join(cells) + " |")
    print()


def synthetic_report(points, nrounds):
    t = lambda p: p["t"]
    s = lambda p: p["samples_per_ray"]
    print(f"Synthetic cases, adaptive against uniform at the same RMSE (all points; errors at least 3× uniform's "
          f"smallest), time from the medians of {nrounds} rounds:\n")
    print("| case | uniform's smallest RMSE | points | uniform ÷ adaptive samples per ray | uniform ÷ adaptive time |")
    print("|---|---:|---:|---|---|")
    for case in dict.fromkeys(p["scan"] for p in points):
        u = [p for p in points if p["scan"] == case and p["stepping"] == "uniform"]
        a = [p for p in points if p["scan"] == case and p["stepping"] == "adaptive"]
        rs = ratios(u, a, s, 3)
        rt = ratios(u, a, t, 3)
        print(f"| {case} | {min(p['rmse'] for p in u)*1e3:.4f}e-3 | {len(rs)} | {span([r for _, r in rs])} | "
              f"{span([r for _, r in rt])} |")
    print()
    print("| case | step | uniform: samples per ray, RMSE, ms | adaptive: samples per ray, mean step, RMSE, ms |")
    print("|---|---:|---|---|")
    for case in dict.fromkeys(p["scan"] for p in points):
        for step in sorted({p["step"] for p in points if p["scan"] == case}):
            cell = {p["stepping"]: p for p in points if p["scan"] == case and p["step"] == step}
            if "adaptive" not in cell:
                continue
            u, a = cell["uniform"], cell["adaptive"]
            print(f"| {case} | {step:g} | {u['samples_per_ray']:.1f}, {u['rmse']*1e3:.4f}e-3, {u['t']:.1f} | "
                  f"{a['samples_per_ray']:.1f}, {a['adaptive_mean_step_voxels']:.2f}, {a['rmse']*1e3:.4f}e-3, {a['t']:.1f} |")
    print()


def main():
    args = sys.argv[1:]
    backend = next((a.split("=", 1)[1] for a in args if a.startswith("--backend=")), None)
    rounds = [a for a in args if not a.startswith("--backend=")]
    if not rounds:
        sys.exit(__doc__)
    keep = lambda points: [p for p in points if backend is None or p["backend"] == backend]
    scans = keep(merge(rounds, "error_vs_time"))
    if scans:
        scans_report(scans, len(rounds))
    synthetic = keep(merge(rounds, "error_synthetic"))
    if synthetic:
        synthetic_report(synthetic, len(rounds))


if __name__ == "__main__":
    main()
