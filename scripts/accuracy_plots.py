#!/usr/bin/python3
"""Plots and tables of the accuracy study (docs/ACCURACY.md) from the CSVs accuracy_study wrote.

usage: accuracy_plots.py DIR      (DIR holds squeeze.csv, sweep.csv, fig6.csv, fig6-rule2.csv, scenes.csv)

Writes DIR/sweep-<error>.png (time against that error, one series per rule, the Pareto front marked)
and DIR/tables.md (every table of docs/ACCURACY.md, from these CSVs). Needs Debian's
python3-matplotlib (run with /usr/bin/python3).
"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

RULES = ["arata", "bingham", "sorted", "prorata"]
COLORS = {"arata": "tab:red", "bingham": "tab:blue", "sorted": "tab:green", "prorata": "tab:purple"}
MARKERS = {"tolerance": "o", "max_steps": "s", "travel": "^", "r0": "D", "m0_over_tc": "v"}

# (column or function, file suffix, axis label, floor for the log axis)
ERRORS = [
    ("residual_rel", "residual", "residual overload / mass"),
    ("heterogeneity_cv", "cv", "heterogeneity CV (interior cells)"),
    ("compaction_excess", "compaction", "compaction - 1 (cells beyond the fewest that hold the clay)"),
    ("one_minus_iou", "iou", "1 - IoU vs the analytic cylinder"),
    ("mean_surface_distance", "surface-distance", "mean surface distance (voxels)"),
    ("abs_radius_err", "radius", "|radius at mid-height - R0 sqrt(H0/H)| / R0 sqrt(H0/H)"),
    ("abs_volume_err", "volume", "|occupied voxels - initial voxels| / initial voxels"),
]


def read(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def derive(row):
    r = {k: v for k, v in row.items()}
    f = lambda k: float(row[k])  # noqa: E731
    r["compaction_excess"] = f("compaction") - 1.0
    r["one_minus_iou"] = 1.0 - f("iou")
    r["abs_radius_err"] = abs(f("radius_mid_err"))
    r["abs_volume_err"] = abs(f("volume_occupied_err_n0"))
    return r


def pareto(points):
    """Indices of the points no other point beats in both time and error (lower is better)."""
    order = sorted(range(len(points)), key=lambda i: (points[i][0], points[i][1]))
    front, best = [], math.inf
    for i in order:
        if points[i][1] < best:
            front.append(i)
            best = points[i][1]
    return front


def plot_sweep(rows, outdir):
    written = []
    for col, suffix, label in ERRORS:
        pts = [(float(r["seconds"]), float(r[col]), r) for r in rows]
        pos = [p[1] for p in pts if p[1] > 0]
        floor = min(pos) / 3 if pos else 1e-9
        plotted = [(max(t, 1e-4), e if e > 0 else floor, r) for t, e, r in pts]
        front = set(pareto([(t, e) for t, e, _ in plotted]))
        fig, ax = plt.subplots(figsize=(8, 5.5))
        for rule in RULES:
            for knob, mk in MARKERS.items():
                sel = [(i, p) for i, p in enumerate(plotted) if p[2]["rule"] == rule and p[2]["knob"] == knob]
                if not sel:
                    continue
                ax.scatter([p[0] for _, p in sel], [p[1] for _, p in sel], marker=mk, s=36,
                           facecolors=[COLORS[rule] if i in front else "none" for i, _ in sel],
                           edgecolors=COLORS[rule], linewidths=1.2)
        fr = sorted((plotted[i] for i in front), key=lambda p: p[0])
        xs, ys = [], []
        for t, e, _ in fr:
            if xs:
                xs.append(t)
                ys.append(ys[-1])
            xs.append(t)
            ys.append(e)
        ax.plot(xs, ys, color="black", lw=1.2, zorder=0, label="Pareto front (filled markers)")
        for t, e, r in fr:
            ax.annotate(f"{r['rule']} {r['knob']}={r['value']}", (t, e), fontsize=6.5, xytext=(4, 3),
                        textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("seconds (whole squeeze, 1 thread; loaded 2-core machine)")
        ax.set_ylabel(label + (f"\n(0 drawn at {floor:.1e})" if any(p[1] <= 0 for p in pts) else ""))
        ax.set_title(f"Squeeze sweep: time against {suffix}")
        handles = [plt.Line2D([], [], color=COLORS[r], marker="o", ls="", label=r) for r in RULES]
        handles += [plt.Line2D([], [], color="gray", marker=m, ls="", mfc="none", label=k) for k, m in MARKERS.items()]
        handles += [plt.Line2D([], [], color="black", lw=1.2, label="Pareto front (filled)")]
        ax.legend(handles=handles, fontsize=7, loc="best", ncol=2)
        ax.grid(True, which="both", alpha=0.25)
        fig.tight_layout()
        name = os.path.join(outdir, f"sweep-{suffix}.png")
        fig.savefig(name, dpi=110)
        plt.close(fig)
        written.append((suffix, name, [plotted[i][2] for i in sorted(front, key=lambda i: plotted[i][0])]))
    return written


def md_table(header, rows):
    out = ["| " + " | ".join(header) + " |", "| " + " | ".join("---" for _ in header) + " |"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def pct(x):
    return f"{100 * float(x):+.1f} %"


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "docs/accuracy"
    md = []
    if os.path.exists(os.path.join(d, "squeeze.csv")):
        sq = read(os.path.join(d, "squeeze.csv"))
        md.append("### Squeeze, per rule and resolution\n")
        md.append(md_table(
            ["rule", "R0", "H0 -> H", "s", "steps", "V mass/Tc vs pi R0^2 H0", "V mass/Tc vs N0",
             "V occupied vs N0", "r mid / ref", "r mid err", "r mean err", "IoU", "surf. dist", "CV", "compaction"],
            [[r["rule"], r["r0"], f"{r['h0']} -> {r['h']}", f"{float(r['seconds']):.2f}", r["steps"],
              pct(r["volume_mass_err"]), pct(r["volume_mass_err_n0"]), pct(r["volume_occupied_err_n0"]),
              f"{float(r['radius_mid']):.2f} / {float(r['radius_ref']):.2f}", pct(r["radius_mid_err"]),
              pct(r["radius_mean_err"]), f"{float(r['iou']):.3f}", f"{float(r['mean_surface_distance']):.2f}",
              f"{float(r['heterogeneity_cv']):.3f}", f"{float(r['compaction']):.3f}"] for r in sq]))
    if os.path.exists(os.path.join(d, "squeeze-profile.csv")):
        prof = read(os.path.join(d, "squeeze-profile.csv"))
        big = max(int(r["r0"]) for r in prof)
        sel = [r for r in prof if int(r["r0"]) == big]
        ys = sorted({int(r["y"]) for r in sel})
        md.append(f"\n### Squeeze profile, R0 = {big}: radius sqrt(occupied cells / pi) per layer (ref "
                  f"{float(sel[0]['radius_ref']):.2f})\n")
        md.append(md_table(["y"] + RULES, [[y] + [next(f"{float(r['radius']):.2f}" for r in sel
                                                       if r["rule"] == rule and int(r["y"]) == y) for rule in RULES]
                                           for y in ys]))
    if os.path.exists(os.path.join(d, "fig6.csv")):
        f6 = read(os.path.join(d, "fig6.csv"))
        md.append("\n### Figure 6: the 2D cylinder, per rule (library, best of 3)\n")
        rows = []
        for rule in RULES:
            fr = [r for r in f6 if r["rule"] == rule]
            steps = [int(r["steps"]) for r in fr]
            secs = [float(r["seconds"]) for r in fr]
            rows.append([rule, len(fr), sum(steps), max(steps), f"{1000 * sum(secs):.1f}", f"{1000 * max(secs):.2f}",
                         sum(int(r["blocks_updated"]) for r in fr), sum(r["stop"] != "settled" for r in fr)])
        md.append(md_table(["rule", "frames", "steps", "max steps / frame", "ms total", "max ms / frame",
                            "blocks updated", "frames unsettled"], rows))
        md.append("\nSteps to stabilise per frame:\n")
        md.append(md_table(["frame"] + RULES, [[f] + [next(r["steps"] for r in f6 if r["rule"] == rule
                                                           and int(r["frame"]) == f) for rule in RULES]
                                               for f in sorted({int(r["frame"]) for r in f6})]))
    if os.path.exists(os.path.join(d, "fig6-rule2.csv")):
        r2 = read(os.path.join(d, "fig6-rule2.csv"))
        md.append("\n### Rule 2 variants (dense 2D re-implementation, 20000-step budget per frame)\n")
        rows = []
        for v in dict.fromkeys(r["variant"] for r in r2):
            fr = [r for r in r2 if r["variant"] == v]
            rows.append([v, sum(int(r["steps"]) for r in fr), f"{sum(float(r['seconds']) for r in fr):.3f}",
                         f"{sum(r['settled'] == '0' for r in fr)} / {len(fr)}", fr[-1]["mass"],
                         max(float(r["residual_overload"]) for r in fr), sum(int(r["e_over_a_blocks"]) for r in fr),
                         sum(int(r["round_up"]) for r in fr), sum(int(r["round_down"]) for r in fr)])
        md.append(md_table(["variant", "steps", "s", "frames unsettled", "final mass", "worst residual at frame end",
                            "E>A updates", "of which gained clay", "lost clay"], rows))
    if os.path.exists(os.path.join(d, "scenes.csv")):
        sc = read(os.path.join(d, "scenes.csv"))
        md.append("\n### Model only what a scene needs\n")
        md.append(md_table(
            ["scene", "D", "active voxels", "leaves", "grid bytes (memUsage)", "leaf bytes", "blocks/step visited",
             "dense clay hull voxels", "hull bytes", "hull blocks/step", "hull / visited", "scene box voxels",
             "box blocks/step"],
            [[r["scene"], r["dims"], r["active_voxels"], r["leaves"], r["grid_bytes"], r["leaf_bytes"],
              r["blocks_visited_per_step"], r["hull_voxels"], r["hull_bytes"], r["hull_blocks_per_step"],
              f"{float(r['hull_blocks_per_step']) / max(1e-9, float(r['blocks_visited_per_step'])):.1f}x",
              r["scene_box_voxels"], r["scene_box_blocks_per_step"]] for r in sc]))
    if os.path.exists(os.path.join(d, "sweep.csv")):
        sw = [derive(r) for r in read(os.path.join(d, "sweep.csv"))]
        md.append("\n### Sweep (base: R0 = 12, H0 = 24 -> H = 12, m0 = 950, Tc = 1000, 1 voxel per frame, settled "
                  "fully)\n")
        md.append(md_table(
            ["rule", "knob", "value", "s", "steps", "frames unsettled", "residual / mass", "CV", "compaction",
             "IoU", "surf. dist", "r mid err", "V occ vs N0"],
            [[r["rule"], r["knob"], r["value"], f"{float(r['seconds']):.3f}", r["steps"], r["frames_unsettled"],
              f"{float(r['residual_rel']):.2e}", f"{float(r['heterogeneity_cv']):.3f}",
              f"{float(r['compaction']):.3f}", f"{float(r['iou']):.3f}", f"{float(r['mean_surface_distance']):.2f}",
              pct(r["radius_mid_err"]), pct(r["volume_occupied_err_n0"])] for r in sw]))
        for suffix, name, front in plot_sweep(sw, d):
            md.append(f"\nPareto front, time against {suffix} ({os.path.basename(name)}): " +
                      "; ".join(f"{r['rule']} {r['knob']}={r['value']} ({float(r['seconds']):.3f} s)" for r in front))
    with open(os.path.join(d, "tables.md"), "w") as f:
        f.write("<!-- generated by scripts/accuracy_plots.py from the CSVs beside it -->\n\n" + "\n".join(md) + "\n")
    print(f"accuracy_plots: wrote {d}/tables.md and the sweep plots")


if __name__ == "__main__":
    main()
