#!/usr/bin/env python3
"""Growth of time and peak memory with the number of rows (issue 28): calibrate --folds 0 and predict
on 10^5, 10^6 and 10^7 poses of iiwa7_clean, each measured by scripts/bench_streaming.sh (GNU time:
wall seconds and peak resident memory), written as a table and drawn log-log.

Writes (default into docs/figures):
  streaming_growth.csv   command, rows, wall_s, peak_mb
  streaming_growth.svg   wall time and peak memory against rows, log-log, with the issue's targets

Standard library only. 10^7 rows need about 4 GB of disk in $TMPDIR and a few minutes:
  cargo build --release
  python3 scripts/streaming_growth.py                  # 1e5, 1e6, 1e7
  python3 scripts/streaming_growth.py --rows 100000,1000000 --out /tmp/g
"""

import argparse
import math
import os
import re
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LINE = re.compile(r"bench_streaming: (.+), (\d+) rows: wall ([0-9.]+) s, peak (\d+) MB")
# The targets at 10^7 rows (wall s, peak MB; None: no target), and at 10^6 for memory.
TARGETS = {
    "calibrate --folds 0": {10_000_000: (60.0, 1024.0), 1_000_000: (None, 150.0)},
    "predict": {10_000_000: (None, 200.0)},
}


def measure(rows, binary):
    env = dict(os.environ)
    if binary:
        env["ROBOCAL_BIN"] = binary
    out = subprocess.run(
        [os.path.join(ROOT, "scripts", "bench_streaming.sh"), str(rows), "calibrate"],
        check=True, capture_output=True, text=True, env=env,
    ).stdout
    found = []
    for line in out.splitlines():
        m = LINE.search(line)
        if m:
            found.append((m.group(1), int(m.group(2)), float(m.group(3)), float(m.group(4))))
            print(line, file=sys.stderr)
    if len(found) != 2:
        sys.exit(f"bench_streaming.sh {rows} printed {len(found)} measurements, expected 2:\n{out}")
    return found


def svg(rows, path):
    commands = []
    for r in rows:
        if r[0] not in commands:
            commands.append(r[0])
    colours = {c: k for c, k in zip(commands, ["#1f77b4", "#d62728", "#2ca02c"])}
    xs = sorted({r[1] for r in rows})
    w, h, m = 340, 280, 60
    panels = [("wall time (s)", 2, 0.1, 1000.0), ("peak resident memory (MB)", 3, 10.0, 10000.0)]
    width = m + len(panels) * (w + m) + 150
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{h + 2 * m + 20}" '
           'font-family="sans-serif" font-size="11">',
           f'<text x="{width / 2}" y="18" text-anchor="middle" font-size="13">iiwa7_clean on the 2-core '
           'machine: growth with the rows, log-log (× marks the issue\'s targets)</text>']
    x_lo, x_hi = xs[0] / 2, xs[-1] * 2

    def pos(x0, lo, hi, x, y):
        lx = (math.log10(x) - math.log10(x_lo)) / (math.log10(x_hi) - math.log10(x_lo))
        ly = (math.log10(y) - math.log10(lo)) / (math.log10(hi) - math.log10(lo))
        return x0 + lx * w, m + h - ly * h

    for k, (label, col, lo, hi) in enumerate(panels):
        x0 = m + k * (w + m)
        out.append(f'<rect x="{x0}" y="{m}" width="{w}" height="{h}" fill="none" stroke="#444"/>')
        out.append(f'<text x="{x0 + w / 2}" y="{m - 8}" text-anchor="middle">{label}</text>')
        for x in xs:
            px, _ = pos(x0, lo, hi, x, lo)
            out.append(f'<text x="{px:.1f}" y="{m + h + 14}" text-anchor="middle">10^{round(math.log10(x))}</text>')
        e = math.ceil(math.log10(lo))
        while 10 ** e <= hi:
            _, py = pos(x0, lo, hi, xs[0], 10 ** e)
            out.append(f'<line x1="{x0}" x2="{x0 + w}" y1="{py:.1f}" y2="{py:.1f}" stroke="#ddd"/>')
            out.append(f'<text x="{x0 - 4}" y="{py + 4:.1f}" text-anchor="end">{10 ** e:g}</text>')
            e += 1
        out.append(f'<text x="{x0 + w / 2}" y="{m + h + 32}" text-anchor="middle">rows (poses)</text>')
        for c in commands:
            pts = [pos(x0, lo, hi, r[1], max(r[col], lo)) for r in rows if r[0] == c]
            out.append('<polyline fill="none" stroke="{}" stroke-width="2" points="{}"/>'.format(
                colours[c], " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)))
            for x, y in pts:
                out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="{colours[c]}"/>')
            for n, target in TARGETS.get(c, {}).items():
                t = target[col - 2]
                if t is None or not x_lo <= n <= x_hi:
                    continue
                x, y = pos(x0, lo, hi, n, t)
                out.append(f'<text x="{x:.1f}" y="{y + 5:.1f}" text-anchor="middle" font-size="15" '
                           f'fill="{colours[c]}">×</text>')
        # A slope of one (time or memory proportional to the rows), through the first point.
        first = [r for r in rows if r[1] == xs[0]]
        if first:
            y1 = max(r[col] for r in first)
            a, b = pos(x0, lo, hi, xs[0], y1), pos(x0, lo, hi, xs[-1], min(y1 * xs[-1] / xs[0], hi))
            out.append(f'<line x1="{a[0]:.1f}" y1="{a[1]:.1f}" x2="{b[0]:.1f}" y2="{b[1]:.1f}" '
                       'stroke="#888" stroke-dasharray="4,4"/>')
    lx = m + len(panels) * (w + m) - 20
    for i, c in enumerate(commands):
        out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 10 + 18 * i}" y2="{m + 10 + 18 * i}" '
                   f'stroke="{colours[c]}" stroke-width="2"/>')
        out.append(f'<text x="{lx + 25}" y="{m + 14 + 18 * i}">{c}</text>')
    i = len(commands)
    out.append(f'<line x1="{lx}" x2="{lx + 20}" y1="{m + 10 + 18 * i}" y2="{m + 10 + 18 * i}" '
               'stroke="#888" stroke-dasharray="4,4"/>')
    out.append(f'<text x="{lx + 25}" y="{m + 14 + 18 * i}">∝ rows</text>')
    out.append("</svg>")
    with open(path + ".tmp", "w") as f:
        f.write("\n".join(out) + "\n")
    os.replace(path + ".tmp", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", default="100000,1000000,10000000")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "figures"))
    ap.add_argument("--robocal", default="", help="the binary (default: bench_streaming.sh builds one)")
    a = ap.parse_args()
    rows = []
    for n in [int(x) for x in a.rows.split(",")]:
        rows.extend(measure(n, a.robocal))
    os.makedirs(a.out, exist_ok=True)
    csv = os.path.join(a.out, "streaming_growth.csv")
    with open(csv + ".tmp", "w") as f:
        f.write("command,rows,wall_s,peak_mb\n")
        for r in rows:
            f.write(f"{r[0]},{r[1]},{r[2]:g},{r[3]:g}\n")
    os.replace(csv + ".tmp", csv)
    svg(rows, os.path.join(a.out, "streaming_growth.svg"))
    print(f"wrote {csv} and streaming_growth.svg")


if __name__ == "__main__":
    main()
