#!/usr/bin/env python3
"""The real-data figures of the README (issue 13): robocal's models on the real robots in
../shared/data/real, judged on poses their fits never saw. Standard library only; runs the robocal
binary as a user would.

1. Hidden test poses: each file split by pose (30 % hidden, seeded); `calibrate --data train
   --test-data hidden` for `--model auto` and `kinematic+learned:kernel` (diagnose, and auto's choice,
   see only the training poses).
2. Learned models on every real robot: 5-fold cross-validation by pose (`calibrate --folds 5`) of the
   kinematic model and of `learned:poly`, `learned:kernel`, `learned:adjoint` on top of it.
3. Two campaigns of the Landgraf UR10: calibrate on series A (every pose), register series B with 20
   of its poses (seeded), predict the rest of B; beside the within-series figures (5-fold) of the same
   models on A and on B.
4. Transfer (issue 24): per robot and model, the held-out poses (5-fold) against the held-out regions
   (`validation.new_region`, 5 regions); for the UR10, A → B and B → A (register 20 poses, predict the
   rest) beside the promise of the series the model was fitted on.

Usage: scripts/real_data_study.py [--robocal PATH] [--out DIR] [--only hidden|learned|campaigns|transfer]
Prints markdown tables; writes every model and JSON report under DIR (default target/real_study).
"""

import argparse
import csv
import json
import math
import os
import random
import subprocess
import sys
import time

REAL = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "data", "real")
if "ROBOCAL_SHARED" in os.environ:
    REAL = os.path.join(os.environ["ROBOCAL_SHARED"], "data", "real")

FILES = {
    "UR5": ("ur5", "ur5_jacobi2025_grid.csv"),
    "WAM": ("wam", "wam_jacobi2025_grid.csv"),
    "UR10 A": ("ur10", "ur10_landgraf2021_seriesA.csv"),
    "UR10 B": ("ur10", "ur10_landgraf2021_seriesB.csv"),
}


def run(robocal, args):
    t = time.time()
    p = subprocess.run([robocal] + args, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"robocal {' '.join(args)} failed ({p.returncode}):\n{p.stderr}")
    return p.stdout, p.stderr, time.time() - t


def read_rows(path):
    with open(path, newline="") as f:
        r = csv.DictReader(f)
        return r.fieldnames, list(r)


def write_rows(path, fields, rows):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)


def split(rows, fraction, seed):
    """Rows of a random `fraction` of the pose ids (seeded) and the others."""
    ids = sorted({r["pose"] for r in rows}, key=int)
    random.Random(seed).shuffle(ids)
    hidden = set(ids[: round(fraction * len(ids))])
    return [r for r in rows if r["pose"] not in hidden], [r for r in rows if r["pose"] in hidden]


def errors(pred_csv, rows):
    _, pred = read_rows(pred_csv)
    assert len(pred) == len(rows)
    e = [math.dist([float(p[k]) for k in "xyz"], [float(m[k]) for k in "xyz"]) for p, m in zip(pred, rows)]
    return {
        "mean": sum(e) / len(e),
        "rms": math.sqrt(sum(x * x for x in e) / len(e)),
        "max": max(e),
        "n": len(e),
    }


def mm(v):
    return f"{v * 1e3:.3f}"


def hidden_poses(robocal, out):
    print("\n### Hidden test poses: `auto` against `kinematic+learned:kernel`\n")
    print("30 % of the poses hidden (split by pose, seed 0); fitted on the rest; held-out mean (RMS) error.\n")
    print("| robot | poses fit / hidden | `auto` chose | `auto` | `kinematic+learned:kernel` |")
    print("|---|---|---|---|---|")
    for name in ["UR5", "UR10 A"]:
        robot, file = FILES[name]
        fields, rows = read_rows(os.path.join(REAL, file))
        train, test = split(rows, 0.3, 0)
        tag = name.replace(" ", "_")
        tr, te = os.path.join(out, f"{tag}_train.csv"), os.path.join(out, f"{tag}_hidden.csv")
        write_rows(tr, fields, train)
        write_rows(te, fields, test)
        cells = []
        chosen = ""
        for model in ["auto", "kinematic+learned:kernel"]:
            so, _, secs = run(robocal, ["calibrate", "--robot", robot, "--data", tr, "--test-data", te,
                                         "--model", model, "--out", os.path.join(out, f"{tag}_{model}.json"), "--json"])
            v = json.loads(so)
            s = v["validation"]["learned"] or v["validation"]["after"]
            cells.append(f"{mm(s['mean_m'])} mm ({mm(s['rms_m'])})")
            if model == "auto":
                chosen = v["model"]
            print(f"  {name} {model}: {secs:.0f} s", file=sys.stderr)
        print(f"| {name} | {len(train)} / {len(test)} | `{chosen}` | {cells[0]} | {cells[1]} |")


def learned_models(robocal, out):
    print("\n### Learned models on every real robot (5-fold cross-validation by pose)\n")
    print("Held-out RMS (mean) error in mm; every fold's model fitted on the other 4/5 of the poses.\n")
    print("| robot | poses | kinematic | + `learned:poly` | + `learned:kernel` | + `learned:adjoint` | adjoint degree |")
    print("|---|---|---|---|---|---|---|")
    for name, (robot, file) in FILES.items():
        path = os.path.join(REAL, file)
        cells, degree, poses = [], "", 0
        for learned in ["", "+learned:poly", "+learned:kernel", "+learned:adjoint"]:
            model = "kinematic" + learned
            so, _, secs = run(robocal, ["calibrate", "--robot", robot, "--data", path, "--model", model,
                                         "--out", os.path.join(out, f"{name.replace(' ', '_')}_{model}.json"), "--json"])
            v = json.loads(so)
            s = v["validation"]["learned"] or v["validation"]["after"]
            poses = s["n_poses"]
            cells.append(f"{mm(s['rms_m'])} ({mm(s['mean_m'])})")
            if learned == "+learned:adjoint":
                d = v["report"]["learned"]["description"]
                degree = d.split("degree ")[1].split(" ")[0] if "degree " in d and v["report"]["learned"]["active"] else "none kept"
            print(f"  {name} {model}: {secs:.0f} s", file=sys.stderr)
        print(f"| {name} | {poses} | " + " | ".join(cells) + f" | {degree} |")


def campaigns(robocal, out):
    print("\n### Two campaigns of the UR10: calibrate on A, register B with 20 poses, predict the rest of B\n")
    a = os.path.join(REAL, FILES["UR10 A"][1])
    fields, b_rows = read_rows(os.path.join(REAL, FILES["UR10 B"][1]))
    ids = sorted({r["pose"] for r in b_rows}, key=int)
    random.Random(1).shuffle(ids)
    reg_ids = set(ids[:20])
    reg = [r for r in b_rows if r["pose"] in reg_ids]
    rest = [r for r in b_rows if r["pose"] not in reg_ids]
    b20, brest = os.path.join(out, "B_register20.csv"), os.path.join(out, "B_rest.csv")
    write_rows(b20, fields, reg)
    write_rows(brest, fields, rest)
    so, _, _ = run(robocal, ["diagnose", "--robot", "ur10", "--data", a, "--json"])
    named = json.loads(so)["model"]
    models = ["kinematic", named, "kinematic+learned:kernel", "kinematic+learned:adjoint", "auto"]
    print("Mean (RMS) position error in mm. Within a series: 5-fold cross-validation by pose. A → B: the model")
    print(f"fitted on every pose of A, B registered on 20 of its poses (seed 1), the other {len(rest)} poses predicted.")
    print(f"Named-cause model: what diagnose chooses on A (`{named}`).\n")
    print("| model | within A (5-fold) | within B (5-fold) | A → B (register 20, predict the rest) | registration residual |")
    print("|---|---|---|---|---|")
    for model in models:
        row = []
        for tag, path in [("A", a), ("B", os.path.join(REAL, FILES["UR10 B"][1]))]:
            mfile = os.path.join(out, f"ur10_{tag}_{model}.json")
            so, _, secs = run(robocal, ["calibrate", "--robot", "ur10", "--data", path, "--model", model,
                                         "--out", mfile, "--json"])
            v = json.loads(so)
            s = v["validation"]["learned"] or v["validation"]["after"]
            row.append(f"{mm(s['mean_m'])} ({mm(s['rms_m'])})")
            chosen = v["model"]
            print(f"  ur10 {tag} {model}: {secs:.0f} s", file=sys.stderr)
        ma = os.path.join(out, f"ur10_A_{model}.json")
        mab = os.path.join(out, f"ur10_AB_{model}.json")
        so, _, secs = run(robocal, ["register", "--model", ma, "--data", b20, "--out", mab, "--json"])
        r = json.loads(so)["report"]
        pred = os.path.join(out, f"ur10_AB_{model}_pred.csv")
        run(robocal, ["predict", "--model", mab, "--data", brest, "--out", pred])
        e = errors(pred, rest)
        label = f"`{model}`" if model != "auto" else f"`auto` (on A: `{chosen}`)"
        print(f"| {label} | {row[0]} | {row[1]} | {mm(e['mean'])} ({mm(e['rms'])}), max {mm(e['max'])} | "
              f"{mm(r['residual']['rms_m'])} RMS, {r['ratio']:.2f}× the model's |")


def register_and_predict(robocal, out, model_file, rows, fields, tag):
    """Registers the campaign `rows` on 20 of its poses (seed 1) with `model_file`; predicts the rest.
    Returns the error statistics and the share of predicted rows outside the support."""
    ids = sorted({r["pose"] for r in rows}, key=int)
    random.Random(1).shuffle(ids)
    reg_ids = set(ids[:20])
    reg = [r for r in rows if r["pose"] in reg_ids]
    rest = [r for r in rows if r["pose"] not in reg_ids]
    r20, rrest = os.path.join(out, f"{tag}_register20.csv"), os.path.join(out, f"{tag}_rest.csv")
    write_rows(r20, fields, reg)
    write_rows(rrest, fields, rest)
    registered = os.path.join(out, f"{tag}_registered.json")
    run(robocal, ["register", "--model", model_file, "--data", r20, "--out", registered])
    pred = os.path.join(out, f"{tag}_pred.csv")
    run(robocal, ["predict", "--model", registered, "--data", rrest, "--out", pred])
    _, p = read_rows(pred)
    outside = sum(int(x["outside_support"]) for x in p) / len(p)
    return errors(pred, rest), outside


def transfer(robocal, out):
    models = ["kinematic", "kinematic+joint_compliance", "kinematic+learned:kernel", "auto"]
    print("\n### What transfers: held-out poses against held-out regions and the other series\n")
    print("Mean position error in mm. *Poses*: 5-fold cross-validation by pose. *Regions*: the poses")
    print("clustered into 5 regions (k-means on sin q, cos q, seed 0), each predicted by the model fitted")
    print("on the others: `validation.new_region`, what the saved model promises for poses unlike its own.\n")
    print("| robot | model | poses | regions |")
    print("|---|---|---|---|")
    promise = {}
    for name, (robot, file) in FILES.items():
        path = os.path.join(REAL, file)
        for model in models:
            tag = f"{name.replace(' ', '_')}_{model}"
            so, _, secs = run(robocal, ["calibrate", "--robot", robot, "--data", path, "--model", model,
                                         "--out", os.path.join(out, f"{tag}.json"), "--json"])
            v = json.loads(so)
            val = v["validation"]
            poses = val["learned"] or val["after"]
            region = val["new_region"]
            promise[(name, model)] = (region["mean_m"], v["model"])
            label = f"`{model}`" if model != "auto" else f"`auto` (`{v['model']}`)"
            print(f"| {name} | {label} | {mm(poses['mean_m'])} | {mm(region['mean_m'])} |")
            print(f"  {name} {model}: {secs:.0f} s", file=sys.stderr)
    print("\n#### The promise against the other series (UR10, register 20 poses, predict the rest)\n")
    print("| model | fitted on | promise (regions of its series) | realised on the other series | rows outside the support |")
    print("|---|---|---|---|---|")
    for src, dst in [("UR10 A", "UR10 B"), ("UR10 B", "UR10 A")]:
        fields, rows = read_rows(os.path.join(REAL, FILES[dst][1]))
        for model in models:
            tag = f"{src.replace(' ', '_')}_{model}"
            e, outside = register_and_predict(robocal, out, os.path.join(out, f"{tag}.json"), rows, fields,
                                              f"{tag}_to_{dst[-1]}")
            p, chosen = promise[(src, model)]
            label = f"`{model}`" if model != "auto" else f"`auto` (`{chosen}`)"
            print(f"| {label} | {src[-1]} → {dst[-1]} | {mm(p)} | {mm(e['mean'])} ({1e2 * (e['mean'] / p - 1):+.0f} %) "
                  f"| {100 * outside:.0f} % |")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--robocal", default=os.path.join("target", "release", "robocal"))
    ap.add_argument("--out", default=os.path.join("target", "real_study"))
    ap.add_argument("--only", choices=["hidden", "learned", "campaigns", "transfer"])
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    if a.only in (None, "hidden"):
        hidden_poses(a.robocal, a.out)
    if a.only in (None, "learned"):
        learned_models(a.robocal, a.out)
    if a.only in (None, "campaigns"):
        campaigns(a.robocal, a.out)
    if a.only in (None, "transfer"):
        transfer(a.robocal, a.out)


if __name__ == "__main__":
    main()
