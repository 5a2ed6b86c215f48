#!/usr/bin/env python3
"""robocal's pose plan against FIGAROH's selection algorithms on the same candidates and information.

For joint compliance on the iiwa 7 (`kinematic+joint_compliance`, payloads 0, 3.5 or 7 kg per pose),
`robocal plan-poses` draws the candidates (configuration x payload), writes every candidate's
information block (`--information-out`: its weighted, scaled Jacobian rows on the identifiable
combinations, so that the information of a selection S is the sum over S of A_k^T A_k) and selects K
poses (greedy D-optimal, then exchanges). The same information matrices X_k = A_k^T A_k then go to
FIGAROH 1.0's own selection algorithms, as its `BaseOptimalCalibration` calls them:

- `SOCPOptimizer` (with --socp): the convex relaxation, max det(sum w_k X_k)^(1/r) over weights
  w >= 0, sum w <= 1 (picos + cvxopt), then the K largest weights; its dense KKT solves grow about as
  n^3 (120 candidates of dimension 36 did not finish in 900 s on the 2-core machine);
- `Detmax`: its exchange heuristic from a random start (Python's `random`, seeded with --seed). FIGAROH
  1.0's `Detmax.main_algo` keeps its set in a local variable (`self.cur_set` stays empty, although
  its docstring says otherwise); the set is read from its last criterion evaluation, which is the
  final set's.

Each selection is valued by the same measures: log det of its information, and the predicted sigma of
every determined stiffness parameter, which `robocal plan-poses` reports when given the selection as
its candidates file (the sigma of a set does not depend on the basis of the identifiable directions).
What is compared is the selection algorithm on one model; FIGAROH's own regressor for elasticity is
not used.

Writes --out (default docs/figures/planned_vs_figaroh.csv): K, method, finished (0 when the method
did not finish within its time, or chose a set that does not determine what the candidates do),
log_det, seconds, then the sigma of each stiffness and its ratio to
robocal's.

Needs numpy, picos and figaroh (not in scripts/requirements.txt: FIGAROH pulls Pinocchio):
    python3 -m venv /tmp/fg && /tmp/fg/bin/pip install figaroh picos pandas pyyaml
    cargo build --release
    /tmp/fg/bin/python scripts/compare_figaroh_plans.py
"""

import argparse
import csv
import io
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def plan(robocal, common, extra):
    """`robocal plan-poses … --json`'s plan, or its one-line error (a selection that determines
    fewer combinations than the candidates do is refused)."""
    cmd = [robocal, "plan-poses", *common, *extra, "--json"]
    print(" ".join(cmd[1:]), file=sys.stderr)
    out = subprocess.run(cmd, capture_output=True, text=True)
    if out.returncode != 0:
        return out.stderr.strip()
    return json.loads(out.stdout)["plan"]


def stiffness_sigmas(p):
    return {x["name"]: x["sigma"] for x in p["parameters"]
            if x["name"].endswith(" compliance") and x["sigma"] is not None}


def read_information(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    nq = sum(1 for h in header if h.startswith("q"))
    a_cols = [i for i, h in enumerate(header) if h.startswith("a")]
    n = len(rows) // 3
    blocks = np.array([[float(rows[3 * c + i][k]) for k in a_cols] for c in range(n) for i in range(3)])
    blocks = blocks.reshape(n, 3, len(a_cols))
    configs = [[float(v) for v in rows[3 * c][1:1 + nq]] for c in range(n)]
    payloads = [float(rows[3 * c][1 + nq]) for c in range(n)]
    return blocks, configs, payloads


def log_det(blocks, chosen):
    if not chosen:
        return float("nan")
    m = sum(blocks[c].T @ blocks[c] for c in chosen)
    sign, v = np.linalg.slogdet(m)
    return v if sign > 0 else float("-inf")


def write_selection(path, configs, payloads, chosen):
    with open(path, "w") as f:
        f.write("pose," + ",".join(f"q{j + 1}" for j in range(len(configs[0]))) + ",payload\n")
        for i, c in enumerate(chosen):
            f.write(f"{i}," + ",".join(repr(v) for v in configs[c]) + f",{payloads[c]!r}\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robocal", default=os.path.join(ROOT, "target", "release", "robocal"))
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "figures", "planned_vs_figaroh.csv"))
    ap.add_argument("--candidates", type=int, default=300)
    ap.add_argument("--select", default="30,60")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-detmax", action="store_true", help="skip FIGAROH's DetMax")
    ap.add_argument("--socp", action="store_true",
                    help="also FIGAROH's SOCP (slow: 120 candidates of dimension 36 did not finish in "
                         "900 s on the 2-core machine)")
    ap.add_argument("--socp-timeout", type=int, default=1200, help="seconds the SOCP may take")
    a = ap.parse_args()
    try:
        from figaroh.optimal.base_optimal_calibration import Detmax, SOCPOptimizer
    except ImportError as e:
        sys.exit(f"compare_figaroh_plans.py needs figaroh and picos: {e}")
    common = ["--robot", "iiwa7", "--model", "kinematic+joint_compliance",
              "--payload-com", "0,0,0.08", "--noise", "1e-5", "--seed", str(a.seed)]
    rows = []
    socp = None  # the SOCP weights do not depend on K: solved once
    with tempfile.TemporaryDirectory() as tmp:
        info = os.path.join(tmp, "information.csv")
        for k in [int(x) for x in a.select.split(",")]:
            t0 = time.perf_counter()
            ours = plan(a.robocal, common, ["--candidates", str(a.candidates), "--payloads", "0,3.5,7",
                                            "--select", str(k), "--information-out", info])
            ours_s = time.perf_counter() - t0
            blocks, configs, payloads = read_information(info)
            n = len(blocks)
            pool = {c: blocks[c].T @ blocks[c] for c in range(n)}
            selections = {"robocal": (ours["candidate_indices"], ours_s)}
            if a.socp and socp is None:
                print(f"FIGAROH SOCP on {n} candidates of dimension {blocks.shape[2]} "
                      f"(at most {a.socp_timeout} s)", file=sys.stderr)
                t0 = time.perf_counter()
                signal.signal(signal.SIGALRM, lambda *_: (_ for _ in ()).throw(TimeoutError()))
                signal.alarm(a.socp_timeout)
                try:
                    _, w_sorted = SOCPOptimizer(pool, {"NbSample": n}).solve()
                    socp = (list(w_sorted.keys()), time.perf_counter() - t0)
                except TimeoutError:
                    socp = (None, time.perf_counter() - t0)
                finally:
                    signal.alarm(0)
                print(f"  {socp[1]:.0f} s", file=sys.stderr)
            if socp is not None and socp[0] is not None:
                selections["figaroh_socp"] = (socp[0][:k], socp[1])
            elif socp is not None:
                rows.append((k, "figaroh_socp", float("nan"), socp[1], {}, None))
            if not a.no_detmax:
                print(f"FIGAROH DetMax, {k} of {n}", file=sys.stderr)
                class Recorded(Detmax):
                    def get_critD(self, chosen):
                        self.last = list(chosen)
                        return super().get_critD(chosen)

                random.seed(a.seed)
                t0 = time.perf_counter()
                d = Recorded(pool, k)
                d.main_algo()
                selections["figaroh_detmax"] = (d.last, time.perf_counter() - t0)
                print(f"  {selections['figaroh_detmax'][1]:.1f} s", file=sys.stderr)
            base = stiffness_sigmas(ours)
            for method, (chosen, seconds) in selections.items():
                chosen = [int(c) for c in chosen]
                sel = os.path.join(tmp, f"{method}_{k}.csv")
                write_selection(sel, configs, payloads, chosen)
                valued = plan(a.robocal, common, ["--candidates-file", sel, "--select", str(k)])
                if isinstance(valued, str):
                    print(f"  {method}: {valued}", file=sys.stderr)
                    rows.append((k, method, log_det(blocks, chosen), seconds, {}, None))
                    continue
                rows.append((k, method, log_det(blocks, chosen), seconds, stiffness_sigmas(valued), base))
    os.makedirs(os.path.dirname(a.out), exist_ok=True)
    names = sorted(next(r[5] for r in rows if r[5]))
    out = io.StringIO()
    out.write("poses,method,finished,log_det,seconds," + ",".join(
        f"sigma_{n.split()[1]},ratio_{n.split()[1]}" for n in names) + "\n")
    for k, method, ld, sec, sig, base in rows:
        if base is None:
            out.write(f"{k},{method},0,{ld:.3f},{sec:.2f}," + ",".join("nan,nan" for _ in names) + "\n")
            continue
        out.write(f"{k},{method},1,{ld:.3f},{sec:.2f}," + ",".join(
            f"{sig.get(n, float('nan')):.4g},{sig.get(n, float('nan')) / base[n]:.3f}" for n in names) + "\n")
    with open(a.out + ".tmp", "w") as f:
        f.write(out.getvalue())
    os.replace(a.out + ".tmp", a.out)
    print(out.getvalue())
    print(f"wrote {a.out} (ratio: σ of the method / σ of robocal's plan; log det of the scaled information)")


if __name__ == "__main__":
    main()
