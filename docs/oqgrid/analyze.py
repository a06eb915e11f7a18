#!/usr/bin/env python3
"""Figures of docs/oqgrid.md from an `occult compare --json` report (stdlib only).

Usage: analyze.py REPORT.json [BASELINE_LABEL]   (baseline: frustum)
Per renderer: mean frame time and speedup over the baseline (ratio of means); the speedup on
the baseline's worst frames (its slowest 10%, ratio of means over those frames, and on its single
slowest frame); triangles rasterized per frame against exactly visible ones (Fig. 5); the share of
cells in the frustum found visible (Fig. 6); triangle throughput (rasterized triangles per second
of frame time, §4.2).
"""
import json
import sys

report = json.load(open(sys.argv[1]))
base_label = sys.argv[2] if len(sys.argv) > 2 else "frustum"
for run in report["runs"]:
    rs = {r["name"]: r for r in run["renderers"]}
    base = [f["time_ms"] for f in rs[base_label]["per_frame"]]
    n = len(base)
    worst = sorted(range(n), key=lambda i: -base[i])[: max(1, n // 10)]
    vis = run["oracle"]["triangles_visible"]
    visible = sum(vis) / len(vis) if isinstance(vis, list) else vis
    print(f"## {run['scene']['name']} ({n} frames, {run['width']}x{run['height']}, {run['threads']} threads)")
    print(f"exactly visible triangles per frame (mean): {visible:,.0f}; oracle mean {run['oracle']['mean_ms']:.1f} ms")
    b = base_label
    print(f"| renderer | mean ms | vs {b} | vs {b}, its slowest 10% | vs {b}, its slowest frame | rasterized/frame | rasterized / visible | cells visible | Mtri/s rasterized |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r in rs.items():
        t = [f["time_ms"] for f in r["per_frame"]]
        mean = sum(t) / n
        sw = sum(base[i] for i in worst) / sum(t[i] for i in worst)
        s1 = base[worst[0]] / t[worst[0]]
        rast = sum(f["triangles_rasterized"] for f in r["per_frame"]) / n
        cv = sum(f.get("counters", {}).get("cells_visible", 0) for f in r["per_frame"])
        cf = sum(f.get("counters", {}).get("cells_in_frustum", 0) for f in r["per_frame"])
        share = f"{100 * cv / cf:.0f}%" if cf else "-"
        thr = rast / mean / 1e3
        print(f"| {name} | {mean:.1f} | {sum(base) / n / mean:.2f}x | {sw:.2f}x | {s1:.2f}x | {rast:,.0f} | {rast / max(visible, 1):.1f}x | {share} | {thr:.2f} |")
    print()
