#!/usr/bin/env python3
"""How many poses, and which payloads, identify each joint stiffness of the iiwa 7 to 5 %?

A worked sensitivity study (issue 27, docs/sweep.md "Worked study"), run as a user would: one
`robocal sweep` of `scenarios/iiwa7_compliance.toml` fitted with `kinematic+joint_compliance`, over
payload sets (`--payloads`) and pose counts, then its parameter table read with pyarrow. For each
payload set, pose count and joint it reports the median over the runs of the predicted relative
standard deviation σ(c)/c of the joint's compliance c = 1/k (to first order that of the stiffness
k), and the mean z² of the compliances' errors against the truth (1 when the σ are honest).

Writes, beside each other in --out (default docs/figures):
  stiffness_study.csv   payloads, poses, joint, runs, sigma_rel_median, z2_mean
  stiffness_study.svg   σ(k)/k against poses, one panel per payload set, one line per joint

Needs pyarrow (pinned in scripts/requirements.txt) and a built robocal:
  cargo build --release
  python3 scripts/study_stiffness.py --reps 20
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile

try:
    import pyarrow.parquet as pq
except ImportError:
    sys.exit("study_stiffness.py needs pyarrow: pip install -r scripts/requirements.txt")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = 0.05


def run_sweep(robocal, out, payloads, poses, reps, seed):
    cmd = [
        robocal, "sweep",
        "--scenario", os.path.join(ROOT, "scenarios", "iiwa7_compliance.toml"),
        "--model", "kinematic+joint_compliance",
        "--payloads", payloads,
        "--noise", "1",
        "--poses", poses,
        "--reps", str(reps),
        "--seed", str(seed),
        "--out", out,
    ]
    print(" ".join(cmd[1:]), file=sys.stderr)
    subprocess.run(cmd, check=True)


def median(v):
    v = sorted(v)
    n = len(v)
    return float("nan") if n == 0 else (v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2]))


def study(wide_path, params_path):
    wide = pq.read_table(wide_path).to_pydict()
    params = pq.read_table(params_path).to_pydict()
    cell_of_run = dict(zip(wide["run"], zip(wide["payloads"], wide["poses"])))
    groups = {}
    for run, name, sigma, truth, z, ident in zip(
        params["run"], params["param"], params["sigma"], params["truth"], params["z"],
        params["identifiable"],
    ):
        if not name.endswith(" compliance") or truth <= 0:
            continue
        joint = int(name.split()[1])
        g = groups.setdefault(cell_of_run[run] + (joint,), {"rel": [], "z2": [], "runs": 0})
        g["runs"] += 1
        g["rel"].append(sigma / truth if ident and math.isfinite(sigma) else math.inf)
        if ident and math.isfinite(z):
            g["z2"].append(z * z)
    rows = []
    for (payloads, poses, joint), g in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2])):
        z2 = sum(g["z2"]) / len(g["z2"]) if g["z2"] else float("nan")
        rows.append((payloads, poses, joint, g["runs"], median(g["rel"]), z2))
    return rows


def svg(rows, path):
    sets = []
    for r in rows:
        if r[0] not in sets:
            sets.append(r[0])
    joints = sorted({r[2] for r in rows})
    poses = sorted({r[1] for r in rows})
    colours = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"]
    w, h, m = 300, 300, 55
    width = m + len(sets) * (w + 20) + 90
    lo, hi = 1e-4, 10.0
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{h + 2 * m + 10}" '
           'font-family="sans-serif" font-size="11">',
           f'<text x="{width / 2}" y="16" text-anchor="middle" font-size="13">iiwa 7: predicted '
           'σ(k)/k of each joint stiffness (median over runs) against poses, per payload set</text>']
    def xy(x0, p, v):
        lx = (math.log10(p) - math.log10(poses[0])) / (math.log10(poses[-1]) - math.log10(poses[0]))
        v = min(max(v, lo), hi)
        ly = (math.log10(v) - math.log10(lo)) / (math.log10(hi) - math.log10(lo))
        return x0 + lx * w, m + h - ly * h
    for k, s in enumerate(sets):
        x0 = m + k * (w + 20)
        out.append(f'<rect x="{x0}" y="{m}" width="{w}" height="{h}" fill="none" stroke="#444"/>')
        out.append(f'<text x="{x0 + w / 2}" y="{m - 8}" text-anchor="middle">payloads {s} kg</text>')
        for p in poses:
            x, _ = xy(x0, p, 1)
            out.append(f'<text x="{x:.1f}" y="{m + h + 14}" text-anchor="middle">{p}</text>')
        for v in [1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0]:
            _, y = xy(x0, poses[0], v)
            out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>')
            if k == 0:
                out.append(f'<text x="{x0 - 4}" y="{y + 4:.1f}" text-anchor="end">{v * 100:g} %</text>')
        _, y5 = xy(x0, poses[0], TARGET)
        out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{y5:.1f}" y2="{y5:.1f}" stroke="#000" '
                   'stroke-dasharray="5,4"/>')
        for j in joints:
            pts = [xy(x0, r[1], r[4]) for r in rows if r[0] == s and r[2] == j and math.isfinite(r[4])]
            if not pts:
                continue
            c = colours[(j - 1) % len(colours)]
            out.append('<polyline fill="none" stroke="{}" stroke-width="1.8" points="{}"/>'.format(
                c, " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)))
            for x, y in pts:
                out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2.5" fill="{c}"/>')
    out.append(f'<text x="{m + len(sets) * (w + 20) / 2}" y="{m + h + 32}" text-anchor="middle">'
               'poses per run (70 % calibrate)</text>')
    lx = m + len(sets) * (w + 20)
    never = [j for j in joints if not any(r[2] == j and math.isfinite(r[4]) for r in rows)]
    joints = [j for j in joints if j not in never]
    if never:
        names = " and ".join(str(j) for j in never)
        out.append(f'<text x="{m}" y="{m + h + 48}">joint{"s" if len(never) > 1 else ""} {names}: '
                   'no stiffness identified at any pose count (no gravity torque that changes)</text>')
    for i, j in enumerate(joints):
        c = colours[(j - 1) % len(colours)]
        out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 10 + 16 * i}" y2="{m + 10 + 16 * i}" '
                   f'stroke="{c}" stroke-width="2"/>')
        out.append(f'<text x="{lx + 25}" y="{m + 14 + 16 * i}">joint {j}</text>')
    out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 14 + 16 * len(joints)}" '
               f'y2="{m + 14 + 16 * len(joints)}" stroke="#000" stroke-dasharray="5,4"/>')
    out.append(f'<text x="{lx + 25}" y="{m + 18 + 16 * len(joints)}">5 %</text>')
    out.append("</svg>")
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(out) + "\n")
    os.replace(path + ".tmp", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robocal", default=os.path.join(ROOT, "target", "release", "robocal"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "figures"))
    ap.add_argument("--payloads", default="0,7,0/3.5/7")
    ap.add_argument("--poses", default="25,50,100,200,400,800")
    ap.add_argument("--reps", type=int, default=40)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    if not os.access(a.robocal, os.X_OK):
        sys.exit(f"{a.robocal}: no robocal binary (cargo build --release, or --robocal PATH)")
    with tempfile.TemporaryDirectory() as tmp:
        wide = os.path.join(tmp, "stiffness.parquet")
        run_sweep(a.robocal, wide, a.payloads, a.poses, a.reps, a.seed)
        rows = study(wide, os.path.join(tmp, "stiffness.params.parquet"))
    os.makedirs(a.out, exist_ok=True)
    csv = os.path.join(a.out, "stiffness_study.csv")
    with open(csv + ".tmp", "w") as f:
        f.write("payloads,poses,joint,runs,sigma_rel_median,z2_mean\n")
        for r in rows:
            f.write(f"{r[0]},{r[1]},{r[2]},{r[3]},{r[4]:.6g},{r[5]:.4g}\n")
    os.replace(csv + ".tmp", csv)
    svg(rows, os.path.join(a.out, "stiffness_study.svg"))
    print(f"wrote {csv} and stiffness_study.svg")
    # The summary: per payload set, the fewest poses giving each joint's stiffness to 5 %.
    sets = []
    for r in rows:
        if r[0] not in sets:
            sets.append(r[0])
    joints = sorted({r[2] for r in rows})
    print("payloads  " + "  ".join(f"joint {j}" for j in joints) + "   (fewest poses for σ(k)/k ≤ 5 %)")
    for s in sets:
        cells = []
        for j in joints:
            ok = [r[1] for r in rows if r[0] == s and r[2] == j and r[4] <= TARGET]
            cells.append(f"{min(ok):>7}" if ok else "      —")
        print(f"{s:>8}  " + "  ".join(cells))
    z2 = [r[5] for r in rows if math.isfinite(r[5])]
    print(f"mean z² per cell and joint: {min(z2):.2f} to {max(z2):.2f}, mean {sum(z2) / len(z2):.2f}")


if __name__ == "__main__":
    main()
