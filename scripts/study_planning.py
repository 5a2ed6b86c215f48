#!/usr/bin/env python3
"""Do planned poses keep their promise for joint compliance, and what do they buy over random ones?

The study of issue 27's item 5 (docs/sweep.md "Planned against random poses"), run as a user would:
two `robocal sweep`s of `scenarios/iiwa7_compliance.toml` fitted with `kinematic+joint_compliance`,
one with `--selection planned` (the training poses and their payloads chosen D-optimally for the
extended model among 10 × the pose count candidates of the scenario's campaign, each with one of its
payloads 0, 3.5 or 7 kg) and one with the scenario's random poses and payloads, the same seed, pose
counts and repetitions. From the parameter tables it reports, per selection, pose count and joint:
the median over the runs of the predicted relative standard deviation σ(c)/c of the joint's
compliance c = 1/k, and the mean z² of the compliance errors against the truth (1 when the σ are
honest); then the ratio random σ / planned σ at equal pose count, and the pose count at which random
poses reach what planned ones give.

Writes, beside each other in --out (default docs/figures):
  planned_vs_random.csv   selection, poses, joint, runs, sigma_rel_median, z2_mean
  planned_vs_random.svg   σ(k)/k against poses, planned (solid) and random (dashed), per joint

Needs pyarrow (pinned in scripts/requirements.txt) and a built robocal:
  cargo build --release
  python3 scripts/study_planning.py --reps 20
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
    sys.exit("study_planning.py needs pyarrow: pip install -r scripts/requirements.txt")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"]


def run_sweep(robocal, out, selection, poses, reps, seed):
    cmd = [
        robocal, "sweep",
        "--scenario", os.path.join(ROOT, "scenarios", "iiwa7_compliance.toml"),
        "--model", "kinematic+joint_compliance",
        "--selection", selection,
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


def study(selection, wide_path, params_path):
    wide = pq.read_table(wide_path).to_pydict()
    params = pq.read_table(params_path).to_pydict()
    poses_of_run = dict(zip(wide["run"], wide["poses"]))
    groups = {}
    for run, name, sigma, truth, z, ident in zip(
        params["run"], params["param"], params["sigma"], params["truth"], params["z"],
        params["identifiable"],
    ):
        if not name.endswith(" compliance") or truth <= 0 or not ident:
            continue
        joint = int(name.split()[1])
        g = groups.setdefault((poses_of_run[run], joint), {"rel": [], "z2": []})
        g["rel"].append(sigma / truth)
        if math.isfinite(z):
            g["z2"].append(z * z)
    rows = []
    for (poses, joint), g in sorted(groups.items()):
        z2 = sum(g["z2"]) / len(g["z2"]) if g["z2"] else float("nan")
        rows.append((selection, poses, joint, len(g["rel"]), median(g["rel"]), z2))
    return rows


def svg(rows, path):
    joints = sorted({r[2] for r in rows})
    poses = sorted({r[1] for r in rows})
    w, h, m = 420, 320, 60
    width = m + w + 150
    vals = [r[4] for r in rows if math.isfinite(r[4]) and r[4] > 0]
    lo = 10 ** math.floor(math.log10(min(vals)))
    hi = 10 ** math.ceil(math.log10(max(vals)))
    def xy(p, v):
        span = math.log10(poses[-1]) - math.log10(poses[0]) or 1.0
        lx = (math.log10(p) - math.log10(poses[0])) / span
        ly = (math.log10(min(max(v, lo), hi)) - math.log10(lo)) / (math.log10(hi) - math.log10(lo))
        return m + lx * w, m + h - ly * h
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{h + 2 * m + 10}" '
           'font-family="sans-serif" font-size="11">',
           f'<text x="{width / 2}" y="18" text-anchor="middle" font-size="13">iiwa 7: predicted '
           'σ(k)/k (median over runs), planned (solid) and random (dashed) poses</text>',
           f'<rect x="{m}" y="{m}" width="{w}" height="{h}" fill="none" stroke="#444"/>']
    for p in poses:
        x, _ = xy(p, lo)
        out.append(f'<text x="{x:.1f}" y="{m + h + 14}" text-anchor="middle">{p}</text>')
    v = lo
    while v <= hi * 1.0001:
        _, y = xy(poses[0], v)
        out.append(f'<line x1="{m}" x2="{m + w}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>')
        out.append(f'<text x="{m - 4}" y="{y + 4:.1f}" text-anchor="end">{v * 100:g} %</text>')
        v *= 10
    out.append(f'<text x="{m + w / 2}" y="{m + h + 32}" text-anchor="middle">'
               'poses per run (70 % calibrate)</text>')
    for j in joints:
        c = COLOURS[(j - 1) % len(COLOURS)]
        for selection, dash in (("planned", ""), ("random", ' stroke-dasharray="6,4"')):
            pts = [xy(r[1], r[4]) for r in rows if r[0] == selection and r[2] == j]
            if not pts:
                continue
            out.append('<polyline fill="none" stroke="{}" stroke-width="1.8"{} points="{}"/>'.format(
                c, dash, " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)))
            for x, y in pts:
                out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2.5" fill="{c}"/>')
    lx = m + w + 15
    for i, j in enumerate(joints):
        c = COLOURS[(j - 1) % len(COLOURS)]
        out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 10 + 16 * i}" y2="{m + 10 + 16 * i}" '
                   f'stroke="{c}" stroke-width="2"/>')
        out.append(f'<text x="{lx + 25}" y="{m + 14 + 16 * i}">joint {j}</text>')
    k = len(joints)
    out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 14 + 16 * k}" y2="{m + 14 + 16 * k}" '
               'stroke="#000"/>')
    out.append(f'<text x="{lx + 25}" y="{m + 18 + 16 * k}">planned</text>')
    out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 30 + 16 * k}" y2="{m + 30 + 16 * k}" '
               'stroke="#000" stroke-dasharray="6,4"/>')
    out.append(f'<text x="{lx + 25}" y="{m + 34 + 16 * k}">random</text>')
    out.append("</svg>")
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(out) + "\n")
    os.replace(path + ".tmp", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robocal", default=os.path.join(ROOT, "target", "release", "robocal"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "figures"))
    ap.add_argument("--poses", default="30,60,120,240")
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--seed", type=int, default=27)
    a = ap.parse_args()
    if not os.access(a.robocal, os.X_OK):
        sys.exit(f"{a.robocal}: no robocal binary (cargo build --release, or --robocal PATH)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for selection in ("planned", "random"):
            wide = os.path.join(tmp, f"{selection}.parquet")
            run_sweep(a.robocal, wide, selection, a.poses, a.reps, a.seed)
            rows += study(selection, wide, os.path.join(tmp, f"{selection}.params.parquet"))
    os.makedirs(a.out, exist_ok=True)
    csv = os.path.join(a.out, "planned_vs_random.csv")
    with open(csv + ".tmp", "w") as f:
        f.write("selection,poses,joint,runs,sigma_rel_median,z2_mean\n")
        for r in rows:
            f.write(f"{r[0]},{r[1]},{r[2]},{r[3]},{r[4]:.6g},{r[5]:.4g}\n")
    os.replace(csv + ".tmp", csv)
    svg(rows, os.path.join(a.out, "planned_vs_random.svg"))
    print(f"wrote {csv} and planned_vs_random.svg")
    cell = {(r[0], r[1], r[2]): r for r in rows}
    joints = sorted({r[2] for r in rows})
    poses = sorted({r[1] for r in rows})
    print("poses  " + "  ".join(f"joint {j}" for j in joints) + "  geometric mean   (random σ / planned σ)")
    for p in poses:
        ratios = [cell[("random", p, j)][4] / cell[("planned", p, j)][4]
                  for j in joints if ("random", p, j) in cell and ("planned", p, j) in cell]
        g = math.exp(sum(math.log(x) for x in ratios) / len(ratios)) if ratios else float("nan")
        print(f"{p:>5}  " + "  ".join(f"{x:>7.2f}" for x in ratios) + f"  {g:>14.2f}")
    for selection in ("planned", "random"):
        z2 = [r[5] for r in rows if r[0] == selection and math.isfinite(r[5])]
        per = {p: [r[5] for r in rows if r[0] == selection and r[1] == p] for p in poses}
        print(f"{selection}: mean z² of the compliances per pose count: "
              + ", ".join(f"{p}: {sum(v) / len(v):.2f}" for p, v in per.items() if v)
              + f" (cells {min(z2):.2f} to {max(z2):.2f})")


if __name__ == "__main__":
    main()
