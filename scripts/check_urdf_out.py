#!/usr/bin/env python3
"""The calibrated URDF (`--urdf-out`) as a drop-in replacement, checked by independent programs.

For the four built-in robots and the two third-party iiwa 7 exports in ../shared/data/robots/, this
script runs robocal as a user would (generate a campaign with drawn kinematic errors, calibrate with
--urdf-out, predict 300 random configurations with --urdf-out) and checks the written URDF:

  * calibrate and predict write the same bytes for the same model;
  * an XML diff against the original (xml.etree, comments kept) shows only the `xyz` / `rpy` of the
    `<origin>` of joints on the chain, which are exactly the joints the comment lists, plus the one
    comment block; a line diff shows only `<origin` lines and that block;
  * MuJoCo 4.0 forward kinematics of the written file (visuals, collisions, gazebo, transmission and
    ros2_control elements stripped in memory, as scripts/mujoco_reference.py does), carried to the
    tracker frame by the comment's `T_tracker_base` and `T_tip_target`, equals robocal predict's target
    positions to 1e-9 m at every configuration;
  * `robocal info` loads the written file with its default chain.

Usage: python scripts/check_urdf_out.py ROBOCAL_BINARY [--shared DIR] [--keep DIR]
Exit status: 0 all checks passed; 1 a check failed (the message says which); 2 bad usage or setup.
"""

import argparse
import csv
import difflib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mujoco  # noqa: E402

from mujoco_reference import (  # noqa: E402
    MASSLESS_EPS,
    build_model,
    load_urdf,
    massless_moving_links,
    mujoco_eval,
    rpy_matrix,
)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MARKER = "robocal-calibration"
TOL_M = 1e-9
N_CONFIGS = 300
SEED = 20261202

# name -> (robocal --robot value relative to its base, base "repo" or "shared", tip link)
ROBOTS = {
    "iiwa7": ("sim/robots/iiwa7.urdf", "repo", "iiwa7_flange", "iiwa7"),
    "ur5": ("sim/robots/ur5.urdf", "repo", "ur5_flange", "ur5"),
    "ur10": ("sim/robots/ur10.urdf", "repo", "ur10_flange", "ur10"),
    "wam": ("sim/robots/wam.urdf", "repo", "wam_flange", "wam"),
    "iiwa_stack_iiwa7": ("data/robots/iiwa_stack_iiwa7.urdf", "shared", "iiwa_link_ee", None),
    "lbr_stack_iiwa7": ("data/robots/lbr_stack_iiwa7.urdf", "shared", "lbr_link_ee", None),
}


class CheckError(Exception):
    pass


def run(cmd):
    p = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
    if p.returncode != 0:
        raise CheckError("%s exited %d: %s" % (" ".join(cmd), p.returncode, p.stderr.strip()))
    return p


def scenario_for(robot_line, out_path):
    """scenarios/iiwa7_kinematic.toml with its [robot] table pointing at another robot."""
    with open(os.path.join(REPO, "scenarios/iiwa7_kinematic.toml")) as f:
        text = f.read()
    new, n = re.subn(r'(?m)^name = "iiwa7".*$', robot_line, text)
    # The iiwa's reachability filter (floor, axis distance) does not suit every robot; the check is
    # about the URDF, not the campaign.
    new, m = re.subn(r"(?m)^floor_z_m = .*$", "floor_z_m = -5.0", new)
    new, m2 = re.subn(r"(?m)^min_axis_distance_m = .*$", "min_axis_distance_m = 0.0", new)
    m += m2
    if n != 1 or m != 2:
        raise CheckError("scenarios/iiwa7_kinematic.toml: its [robot] name or campaign filter lines changed")
    with open(out_path, "w") as f:
        f.write(new)


def comment_origin(text, key):
    m = re.search(r'%s: <origin xyz="([^"]+)"(?: rpy="([^"]+)")?/>' % key, text)
    if not m:
        raise CheckError("the comment has no '%s: <origin .../>' line" % key)
    xyz = np.array([float(v) for v in m.group(1).split()])
    rpy = [float(v) for v in m.group(2).split()] if m.group(2) else [0.0, 0.0, 0.0]
    return xyz, rpy_matrix(rpy)


def changed_joints_in_comment(text):
    m = re.search(r"differ from it:\n\s*(.*)\n", text)
    if not m:
        raise CheckError("the comment does not list the changed joints")
    line = m.group(1).strip()
    return [] if line.startswith("(none") else [s.strip() for s in line.split(",")]


def parse_with_comments(path):
    return ET.parse(path, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True))).getroot()


def xml_diff(orig, new, chain_joints):
    """Element-by-element comparison; returns the joints whose origin changed."""
    changed = set()
    kids_o, kids_n = list(orig), list(new)
    extra = [c for c in kids_n if c.tag is ET.Comment and c.text.strip().startswith(MARKER)]
    if len(extra) != 1:
        raise CheckError("expected one %s comment under <robot>, found %d" % (MARKER, len(extra)))
    kids_n = [c for c in kids_n if c is not extra[0]]
    if (orig.tag, orig.attrib) != (new.tag, new.attrib):
        raise CheckError("the <robot> element changed")

    def walk(a, b, path, joint):
        if a.tag != b.tag or (a.text or "").strip() != (b.text or "").strip():
            raise CheckError("%s: element or text changed" % path)
        if a.attrib != b.attrib:
            if not (a.tag == "origin" and joint is not None):
                raise CheckError("%s: attributes changed: %r -> %r" % (path, a.attrib, b.attrib))
            keys = set(a.attrib) | set(b.attrib)
            if not keys <= {"xyz", "rpy"}:
                raise CheckError("%s: attributes other than xyz/rpy changed" % path)
            if joint not in chain_joints:
                raise CheckError("%s: joint %s is not on the chain but its origin changed" % (path, joint))
            changed.add(joint)
        ca, cb = list(a), list(b)
        if len(ca) != len(cb):
            # a joint without <origin> gets one as its first child
            if joint is not None and len(cb) == len(ca) + 1 and cb[0].tag == "origin":
                changed.add(joint)
                cb = cb[1:]
            else:
                raise CheckError("%s: children changed" % path)
        for x, y in zip(ca, cb):
            walk(x, y, path + "/" + str(x.tag if x.tag is not ET.Comment else "comment"), joint)

    if len(kids_o) != len(kids_n):
        raise CheckError("<robot> has %d children, was %d" % (len(kids_n), len(kids_o)))
    for a, b in zip(kids_o, kids_n):
        joint = a.get("name") if a.tag == "joint" else None
        walk(a, b, "robot/%s[%s]" % (a.tag if a.tag is not ET.Comment else "comment", a.get("name")), joint)
    return changed


def line_diff(orig_text, new_text):
    """Every line added or removed is an <origin> line or part of the comment block."""
    in_block = False
    for d in difflib.ndiff(orig_text.splitlines(), new_text.splitlines()):
        if d.startswith("? "):
            continue
        line = d[2:]
        if d.startswith("+ ") and MARKER in line:
            in_block = True
        if d[0] in "+-":
            if not (in_block or line.strip().startswith("<origin")):
                raise CheckError("line diff shows a line that is not an <origin>: %r" % d)
        if in_block and line.strip() == "-->":
            in_block = False


def check_robot(name, robocal, shared, work):
    rel, base, tip, builtin = ROBOTS[name]
    urdf_path = os.path.join(REPO if base == "repo" else shared, rel)
    robot_arg = builtin or urdf_path
    d = os.path.join(work, name)
    os.makedirs(d)
    scen = os.path.join(d, "scenario.toml")
    scenario_for('name = "%s"' % builtin if builtin else 'urdf = "%s"' % urdf_path, scen)
    run([robocal, "generate", "--scenario", scen, "--out", os.path.join(d, "gen"), "--poses", "60",
         "--seed", "3"])
    model = os.path.join(d, "model.json")
    cal_urdf = os.path.join(d, "calibrate.urdf")
    run([robocal, "calibrate", "--robot", robot_arg, "--data", os.path.join(d, "gen/measurements.parquet"),
         "--out", model, "--urdf-out", cal_urdf])

    _, desc = load_urdf(urdf_path, tip)
    n = len(desc["movable"])
    lower = np.array([j["lower"] for j in desc["movable"]])
    upper = np.array([j["upper"] for j in desc["movable"]])
    Q = np.random.default_rng(SEED).uniform(lower, upper, size=(N_CONFIGS, n))
    configs = os.path.join(d, "configs.csv")
    with open(configs, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["pose"] + ["q%d" % (i + 1) for i in range(n)])
        for k, q in enumerate(Q):
            w.writerow([k] + [repr(float(v)) for v in q])
    pred_csv = os.path.join(d, "pred.csv")
    pred_urdf = os.path.join(d, "predict.urdf")
    run([robocal, "predict", "--model", model, "--data", configs, "--out", pred_csv, "--urdf-out", pred_urdf])

    with open(cal_urdf, "rb") as f, open(pred_urdf, "rb") as g:
        if f.read() != g.read():
            raise CheckError("%s: calibrate --urdf-out and predict --urdf-out differ" % name)
    with open(urdf_path) as f:
        orig_text = f.read()
    with open(pred_urdf) as f:
        new_text = f.read()

    # The XML diff: only chain origins and the comment.
    chain = []
    link = tip
    while link != desc["root"]:
        j = desc["joints"][link]
        chain.append(j["name"])
        link = j["parent"]
    changed = xml_diff(parse_with_comments(urdf_path), parse_with_comments(pred_urdf), set(chain))
    listed = changed_joints_in_comment(new_text)
    if sorted(changed) != sorted(listed):
        raise CheckError("%s: origins changed %s, the comment lists %s" % (name, sorted(changed), listed))
    if not set(j["name"] for j in desc["movable"]) <= changed:
        raise CheckError("%s: not every movable joint's origin changed: %s" % (name, sorted(changed)))
    line_diff(orig_text, new_text)

    # MuJoCo forward kinematics of the written file, to the tracker frame through the comment.
    xml, desc_new = load_urdf(pred_urdf, tip)
    eps = MASSLESS_EPS if massless_moving_links(desc_new) else 0.0
    m = build_model(xml, desc_new, eps=eps)
    data = mujoco.MjData(m)
    root_id, tip_id = m.body(desc_new["root"]).id, m.body(tip).id
    p_base, R_base = comment_origin(new_text, "T_tracker_base")
    p_target, _ = comment_origin(new_text, "T_tip_target")
    with open(pred_csv) as f:
        rows = list(csv.DictReader(f))
    if len(rows) != N_CONFIGS:
        raise CheckError("%s: predict wrote %d rows" % (name, len(rows)))
    worst = 0.0
    for q, row in zip(Q, rows):
        p, R, _ = mujoco_eval(m, data, root_id, tip_id, q)
        p_tracker = p_base + R_base @ (p + R @ p_target)
        expected = np.array([float(row[k]) for k in ("x", "y", "z")])
        worst = max(worst, float(np.linalg.norm(p_tracker - expected)))
    if not worst <= TOL_M:
        raise CheckError("%s: MuJoCo FK of the written URDF is %.3g m from robocal predict" % (name, worst))

    info = json.loads(run([robocal, "info", "--robot", pred_urdf, "--json"]).stdout)
    if (info["tip_link"], len(info["joints"])) != (tip, n):
        raise CheckError("%s: robocal info loads the written file as %s, %d joints"
                         % (name, info["tip_link"], len(info["joints"])))
    print("%-18s %d origins changed (%s … %s), XML diff clean; MuJoCo FK vs predict: max %.1e m over %d configs"
          % (name, len(changed), chain[-1], chain[0], worst, N_CONFIGS))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("robocal", help="the robocal binary")
    ap.add_argument("--shared", default=os.environ.get("ROBOCAL_SHARED", os.path.join(REPO, "..", "shared")))
    ap.add_argument("--keep", help="keep the work files in this folder")
    args = ap.parse_args()
    if not os.access(args.robocal, os.X_OK):
        print("%s: not an executable" % args.robocal, file=sys.stderr)
        return 2
    robocal = os.path.abspath(args.robocal)
    work = args.keep or tempfile.mkdtemp(prefix="robocal_urdf_out_")
    os.makedirs(work, exist_ok=True)
    try:
        for name in ROBOTS:
            check_robot(name, robocal, args.shared, work)
    except CheckError as e:
        print("check_urdf_out: FAILED: %s" % e, file=sys.stderr)
        return 1
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    print("check_urdf_out: all %d URDFs OK" % len(ROBOTS))
    return 0


if __name__ == "__main__":
    sys.exit(main())
