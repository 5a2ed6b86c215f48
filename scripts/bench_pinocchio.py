#!/usr/bin/env python3
"""Times Pinocchio on the kinematics of sim/benches/kinematics.rs and prints it beside robocal's numbers.

What is measured (same robot, same configurations, same operations as the criterion bench):

  * robot: the iiwa 7 URDF `sim/robots/iiwa7.urdf` (or `--urdf`), tip frame `iiwa7_flange` (`--tip-link`);
  * configurations: the bench's 64, q_k[i] = frac((k+1)(0.618034 + 0.414214 i)) * 4 - 2, k = 0..63,
    i = 0..6, cycled through call after call as `k = (k+1) % 64` exactly as in the bench;
  * `flange_pose`: pose of the flange frame in the base (root link) frame. Pinocchio:
    `forwardKinematics` + `updateFramePlacement(flange)`;
  * `flange_pose_and_position_jacobian`: the same plus the 3x7 position Jacobian, in base-frame
    coordinates, of the point 0.05 m along the flange z axis. Pinocchio: an OP_FRAME "robocal_tool" is
    added at flange * (0, 0, 0.05); `forwardKinematics` + `updateFramePlacement(flange)` +
    `computeFrameJacobian(tool, LOCAL_WORLD_ALIGNED)`, translation rows. Note that computeFrameJacobian
    runs its own forward pass over the tool's support (all 7 joints), so this sequence does the
    kinematics twice;
  * `... (one pass)`: the same result with a single forward pass, Pinocchio's cheapest sequence for it:
    `computeJointJacobians` + `updateFramePlacement(flange)` + `getFrameJacobian(tool,
    LOCAL_WORLD_ALIGNED)`, translation rows. robocal's column repeats its pose-and-Jacobian number.

Columns:
  * robocal: criterion's mean point estimate (ns) from
    target/criterion/iiwa7_flange_pose/new/estimates.json and
    target/criterion/iiwa7_flange_pose_and_position_jacobian/new/estimates.json (run
    `cargo bench -p sim --bench kinematics` first; otherwise the column says so);
  * Pinocchio Python: per-call time through the Python bindings (pin 4.1), binding overhead and the
    Python `for` loop included (the bare loop's cost is printed under the table, not subtracted), from
    time.perf_counter_ns around `--reps` calls (default 200,000), best of `--runs` runs (default 5),
    garbage collector off;
  * Pinocchio C++: scripts/bench_pinocchio.cpp, compiled on demand into target/pinocchio_bench/ with
    g++ -O3 -march=x86-64 and linked against the Pinocchio C++ library shipped inside the `pin` wheel
    (libpinocchio_default.so, libpinocchio_parsers.so in the venv's site-packages/cmeel.prefix/lib; built
    with PINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION, so the algorithms run the wheel's compiled code);
    std::chrono::steady_clock around `--cxx-reps` calls (default 1,000,000), best of `--runs` runs. The
    wheel has neither Eigen's headers nor urdfdom's, both needed to compile against Pinocchio's headers:
    they come from the cmeel packages `cmeel-eigen` (3.4.1, the Eigen eigenpy/pin are built with) and
    `cmeel-urdfdom-headers` (3.0.0, the version Pinocchio was built with). Without them, or without g++,
    the column says why it is empty;
  * ratios: Pinocchio time / robocal time (> 1: robocal is faster).

Correctness checked on every run (exit status 3 if one fails, before any timing): for all 64
configurations the flange position and rotation from Pinocchio (Python) must equal a plain numpy
product of the URDF's joint transforms to 1e-12, and the tool-point position Jacobian must equal the
numpy geometric Jacobian (w_j x (p - o_j)) to 1e-12; the C++ harness's configurations must be
bit-identical to Python's and its flange positions and Jacobians equal to Python's to 1e-12; and, if a
robocal binary is already built (target/release/robocal or target/debug/robocal; this script never
builds it), `robocal fk --json` at configurations k = 0, 21, 42 must give the same flange position and
rotation to 1e-12.

How to run (from the repository root):

  python3 -m venv /tmp/pinv
  /tmp/pinv/bin/pip install pin==4.1.0 numpy cmeel-eigen==3.4.1 cmeel-urdfdom-headers==3.0.0
  cargo bench -p sim --bench kinematics -- --warm-up-time 1 --measurement-time 3   # robocal's column
  /tmp/pinv/bin/python scripts/bench_pinocchio.py [--urdf FILE] [--tip-link LINK] [--reps N]
      [--cxx-reps N] [--runs N] [--no-cxx] [--rebuild]

The first run compiles the C++ harness (about a minute); later runs reuse the binary unless the source,
the compiler command line or the cmeel prefix changed (`--rebuild` forces it). Timings on a machine
that is busy with other work are noisy: compare numbers taken at the same time, and rerun.

Exit status: 0 OK (also when the robocal or C++ column is empty, with the reason printed);
2 Pinocchio/numpy not importable or the URDF/tip link unusable; 3 a correctness check failed.
"""

import argparse
import gc
import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CXX_SOURCE = os.path.join(REPO, "scripts", "bench_pinocchio.cpp")
BUILD_DIR = os.path.join(REPO, "target", "pinocchio_bench")
TOL = 1e-12
TOOL_OFFSET_Z = 0.05  # m along the flange z axis, as `tool` in sim/benches/kinematics.rs
CRITERION = {
    "flange_pose": "iiwa7_flange_pose",
    "flange_pose_and_position_jacobian": "iiwa7_flange_pose_and_position_jacobian",
}

try:
    import numpy as np
    import pinocchio as pin
except ImportError as e:  # pragma: no cover - environment problem
    print(f"error: {e}\nInstall the Python side first:\n"
          "  python3 -m venv /tmp/pinv && /tmp/pinv/bin/pip install pin==4.1.0 numpy "
          "cmeel-eigen==3.4.1 cmeel-urdfdom-headers==3.0.0\n"
          "and run this script with /tmp/pinv/bin/python.", file=sys.stderr)
    sys.exit(2)


def configs(n_joints):
    """The criterion bench's 64 configurations: frac((k+1)(0.618034 + 0.414214 i)) * 4 - 2.

    Same floating-point operations in the same order as the Rust code; the argument is positive, so
    x - floor(x) equals Rust's f64::fract exactly.
    """
    out = []
    for k in range(64):
        row = []
        for i in range(n_joints):
            x = (float(k) + 1.0) * (0.618034 + 0.414214 * float(i))
            row.append((x - math.floor(x)) * 4.0 - 2.0)
        out.append(row)
    return out


# --------------------------------------------------------------------------------------------------
# Independent numpy forward kinematics straight from the URDF text.

def _floats(s, default):
    return [float(v) for v in s.split()] if s is not None else list(default)


def _rpy(r, p, y):
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _axis_angle(a, t):
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(t) * k + (1.0 - math.cos(t)) * (k @ k)


def urdf_chain(path, tip):
    """Joints from the root link to `tip`: list of (name, type, origin 4x4, unit axis)."""
    root = ET.parse(path).getroot()
    by_child = {}
    for j in root.findall("joint"):
        by_child[j.find("child").get("link")] = j
    if tip not in by_child:
        raise ValueError(f"link {tip!r} is not the child of any joint in {path}")
    chain, link = [], tip
    while link in by_child:
        j = by_child[link]
        o = j.find("origin")
        xyz = _floats(o.get("xyz") if o is not None else None, (0, 0, 0))
        rpy = _floats(o.get("rpy") if o is not None else None, (0, 0, 0))
        t = np.eye(4)
        t[:3, :3] = _rpy(*rpy)
        t[:3, 3] = xyz
        a = j.find("axis")
        axis = np.array(_floats(a.get("xyz") if a is not None else None, (1, 0, 0)))
        kind = j.get("type")
        if kind not in ("revolute", "continuous", "prismatic", "fixed"):
            raise ValueError(f"joint {j.get('name')!r}: type {kind!r} not handled")
        if j.find("mimic") is not None:
            raise ValueError(f"joint {j.get('name')!r}: mimic joints not handled")
        chain.append((j.get("name"), kind, t, axis / np.linalg.norm(axis) if kind != "fixed" else axis))
        link = j.find("parent").get("link")
    chain.reverse()
    return chain


def numpy_fk(chain, q, tool_offset):
    """Flange pose (4x4) and position Jacobian (3 x n) of flange * tool_offset, base frame."""
    t = np.eye(4)
    origins, axes, kinds = [], [], []
    qi = 0
    for _name, kind, origin, axis in chain:
        t = t @ origin
        if kind == "fixed":
            continue
        m = np.eye(4)
        if kind == "prismatic":
            m[:3, 3] = axis * q[qi]
        else:
            m[:3, :3] = _axis_angle(axis, q[qi])
        origins.append(t[:3, 3].copy())
        axes.append(t[:3, :3] @ axis)
        kinds.append(kind)
        t = t @ m
        qi += 1
    p = t[:3, :3] @ tool_offset + t[:3, 3]
    jac = np.zeros((3, len(kinds)))
    for c, (o, w, kind) in enumerate(zip(origins, axes, kinds)):
        jac[:, c] = w if kind == "prismatic" else np.cross(w, p - o)
    return t, jac


# --------------------------------------------------------------------------------------------------

def criterion_mean_ns(name):
    path = os.path.join(REPO, "target", "criterion", name, "new", "estimates.json")
    try:
        with open(path) as f:
            return float(json.load(f)["mean"]["point_estimate"])
    except (OSError, KeyError, ValueError):
        return None


def best_per_call_ns(fn, seq, runs):
    """Best of `runs` timings of fn over every element of seq, in ns per call."""
    best = math.inf
    fn(seq[: min(len(seq), 20000)])  # warm-up
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(runs):
            t0 = time.perf_counter_ns()
            fn(seq)
            t1 = time.perf_counter_ns()
            best = min(best, (t1 - t0) / len(seq))
    finally:
        if gc_was_enabled:
            gc.enable()
    return best


def cmeel_prefix():
    for p in sys.path:
        c = os.path.join(p, "cmeel.prefix")
        if os.path.isdir(os.path.join(c, "include", "pinocchio")):
            return c
    return None


def build_cxx(rebuild):
    """Compile scripts/bench_pinocchio.cpp if needed. Returns (binary path, None) or (None, reason)."""
    prefix = cmeel_prefix()
    if prefix is None:
        return None, "no cmeel.prefix with include/pinocchio on sys.path (is `pin` installed from PyPI?)"
    inc, lib = os.path.join(prefix, "include"), os.path.join(prefix, "lib")
    missing = []
    if not os.path.isfile(os.path.join(inc, "eigen3", "Eigen", "Core")):
        missing.append("Eigen headers (pip install cmeel-eigen==3.4.1)")
    if not os.path.isfile(os.path.join(inc, "urdfdom_headers", "urdf_model", "model.h")):
        missing.append("urdfdom headers (pip install cmeel-urdfdom-headers==3.0.0)")
    for so in ("libpinocchio_default.so", "libpinocchio_parsers.so", "liburdfdom_model.so"):
        if not os.path.isfile(os.path.join(lib, so)):
            missing.append(f"{so} in {lib}")
    cxx = os.environ.get("CXX", "g++")
    if shutil.which(cxx) is None:
        missing.append(f"C++ compiler {cxx!r} (apt-get install g++)")
    if missing:
        return None, "C++ harness not built, missing: " + "; ".join(missing)
    out = os.path.join(BUILD_DIR, "bench_pinocchio")
    cmd = [
        cxx, "-std=c++17", "-O3", "-march=x86-64", "-DNDEBUG",
        # As pinocchio::pinocchio_default / pinocchio_parsers' INTERFACE_COMPILE_DEFINITIONS in
        # cmeel.prefix/lib/cmake/pinocchio/pinocchioTargets.cmake.
        "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION", "-DPINOCCHIO_WITH_URDFDOM",
        "-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
        "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
        f"-I{inc}", f"-I{os.path.join(inc, 'eigen3')}", f"-I{os.path.join(inc, 'urdfdom_headers')}",
        f"-I{os.path.join(inc, 'urdfdom')}",
        CXX_SOURCE, "-o", out,
        f"-L{lib}", f"-Wl,-rpath,{lib}",
        "-lpinocchio_parsers", "-lpinocchio_default", "-lurdfdom_model", "-lboost_filesystem",
        "-lboost_serialization",
    ]
    with open(CXX_SOURCE, "rb") as f:
        stamp = hashlib.sha256(f.read() + "\0".join(cmd).encode()).hexdigest()
    stamp_path = out + ".stamp"
    if not rebuild and os.path.isfile(out) and os.path.isfile(stamp_path):
        with open(stamp_path) as f:
            if f.read().strip() == stamp:
                return out, None
    os.makedirs(BUILD_DIR, exist_ok=True)
    print("compiling the C++ harness (about a minute):\n  " + " ".join(cmd), file=sys.stderr)
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        tail = "\n".join(r.stderr.strip().splitlines()[-15:])
        return None, f"C++ harness failed to compile (exit {r.returncode}):\n{tail}"
    with open(stamp_path, "w") as f:
        f.write(stamp + "\n")
    return out, None


def find_robocal():
    for profile in ("release", "debug"):
        p = os.path.join(REPO, "target", profile, "robocal")
        if os.path.isfile(p) and os.access(p, os.X_OK):
            return p
    return None


def fail(msg):
    print(f"CHECK FAILED: {msg}", file=sys.stderr)
    sys.exit(3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--urdf", default=os.path.join(REPO, "sim", "robots", "iiwa7.urdf"))
    ap.add_argument("--tip-link", default="iiwa7_flange")
    ap.add_argument("--reps", type=int, default=200_000, help="Python calls per timed run (default 200000)")
    ap.add_argument("--cxx-reps", type=int, default=1_000_000, help="C++ calls per timed run (default 1000000)")
    ap.add_argument("--runs", type=int, default=5, help="timed runs, best one kept (default 5)")
    ap.add_argument("--no-cxx", action="store_true", help="skip the C++ harness")
    ap.add_argument("--rebuild", action="store_true", help="recompile the C++ harness")
    args = ap.parse_args()
    if args.reps < 1 or args.cxx_reps < 1 or args.runs < 1:
        ap.error("--reps, --cxx-reps and --runs must be positive")

    # ---- model -----------------------------------------------------------------------------------
    try:
        chain = urdf_chain(args.urdf, args.tip_link)
        model = pin.buildModelFromUrdf(args.urdf)
    except (OSError, ValueError, RuntimeError, ET.ParseError) as e:
        print(f"error: {e}", file=sys.stderr)
        sys.exit(2)
    if not model.existFrame(args.tip_link):
        print(f"error: Pinocchio has no frame {args.tip_link!r}", file=sys.stderr)
        sys.exit(2)
    flange = model.getFrameId(args.tip_link)
    ff = model.frames[flange]
    tool_placement = ff.placement * pin.SE3(np.eye(3), np.array([0.0, 0.0, TOOL_OFFSET_Z]))
    tool = model.addFrame(pin.Frame("robocal_tool", ff.parentJoint, flange, tool_placement, pin.FrameType.OP_FRAME))
    data = model.createData()
    moving = [c for c in chain if c[1] != "fixed"]
    n = len(moving)
    if model.nq != n or model.nv != n:
        print(f"error: chain to {args.tip_link!r} has {n} joints, Pinocchio model nq={model.nq}: "
              "this script handles a single serial chain", file=sys.stderr)
        sys.exit(2)
    # Chain order (robocal's q order) -> Pinocchio's idx_q / idx_v.
    idx_q = [model.joints[model.getJointId(c[0])].idx_q for c in moving]
    idx_v = [model.joints[model.getJointId(c[0])].idx_v for c in moving]
    q_chain = configs(n)
    qs = []
    for row in q_chain:
        q = np.zeros(model.nq)
        q[idx_q] = row
        qs.append(q)
    tool_offset = np.array([0.0, 0.0, TOOL_OFFSET_Z])
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    # ---- correctness: Pinocchio (Python) vs numpy --------------------------------------------------
    worst_p = worst_r = worst_j = 0.0
    pin_pos, pin_jac = [], []
    for row, q in zip(q_chain, qs):
        t_ref, j_ref = numpy_fk(chain, row, tool_offset)
        pin.forwardKinematics(model, data, q)
        m = pin.updateFramePlacement(model, data, flange)
        jac = pin.computeFrameJacobian(model, data, q, tool, lwa)[:3][:, idx_v]
        pin_pos.append(m.translation.copy())
        pin_jac.append(jac.copy())
        worst_p = max(worst_p, float(np.abs(m.translation - t_ref[:3, 3]).max()))
        worst_r = max(worst_r, float(np.abs(m.rotation - t_ref[:3, :3]).max()))
        worst_j = max(worst_j, float(np.abs(jac - j_ref).max()))
    if max(worst_p, worst_r, worst_j) > TOL:
        fail(f"Pinocchio vs numpy FK: position {worst_p:.3g} m, rotation {worst_r:.3g}, "
             f"Jacobian {worst_j:.3g} m/rad (tolerance {TOL})")
    checks = [f"Pinocchio vs numpy product of URDF transforms, 64 configurations: max |dp| {worst_p:.1e} m, "
              f"max |dR| {worst_r:.1e}, max |dJ| {worst_j:.1e} m/rad"]

    robocal = find_robocal()
    if robocal is None:
        checks.append("robocal fk: no built binary in target/release or target/debug, skipped "
                      "(this script never builds it)")
    else:
        worst_fp = worst_fr = 0.0
        for k in (0, 21, 42):
            qarg = ",".join(repr(v) for v in q_chain[k])
            r = subprocess.run([robocal, "fk", "--robot", args.urdf, "--tip-link", args.tip_link,
                                f"--q={qarg}", "--json"], capture_output=True, text=True)
            if r.returncode != 0:
                fail(f"robocal fk exited {r.returncode}: {r.stderr.strip()}")
            doc = json.loads(r.stdout)
            pin.forwardKinematics(model, data, qs[k])
            m = pin.updateFramePlacement(model, data, flange)
            worst_fp = max(worst_fp, float(np.abs(np.array(doc["position_m"]) - m.translation).max()))
            worst_fr = max(worst_fr, float(np.abs(np.array(doc["rotation"]) - m.rotation).max()))
        if max(worst_fp, worst_fr) > TOL:
            fail(f"Pinocchio vs `robocal fk`: position {worst_fp:.3g} m, rotation {worst_fr:.3g}")
        checks.append(f"Pinocchio vs `{os.path.relpath(robocal, REPO)} fk --json`, k = 0, 21, 42: "
                      f"max |dp| {worst_fp:.1e} m, max |dR| {worst_fr:.1e}")

    # ---- C++ harness -----------------------------------------------------------------------------
    cxx = {}
    cxx_note = None
    if args.no_cxx:
        cxx_note = "C++ harness skipped (--no-cxx)"
    else:
        binary, cxx_note = build_cxx(args.rebuild)
        if binary is not None:
            r = subprocess.run([binary, args.urdf, args.tip_link, str(args.cxx_reps), str(args.runs)],
                               capture_output=True, text=True)
            if r.returncode != 0:
                cxx_note = f"C++ harness exited {r.returncode}: {r.stderr.strip()}"
            else:
                cxx = json.loads(r.stdout)
                if cxx["q"] != [list(map(float, row)) for row in q_chain]:
                    fail("C++ configurations differ from Python's")
                dp = max(float(np.abs(np.array(a) - b).max()) for a, b in zip(cxx["flange_position"], pin_pos))
                dj = max(float(np.abs(np.array(a)[:, idx_v] - b).max())
                         for a, b in zip(cxx["tool_position_jacobian"], pin_jac))
                if max(dp, dj) > TOL:
                    fail(f"C++ vs Python Pinocchio: position {dp:.3g} m, Jacobian {dj:.3g}")
                checks.append(f"Pinocchio C++ vs Python, 64 configurations: configurations bit-identical, "
                              f"max |dp| {dp:.1e} m, max |dJ| {dj:.1e} m/rad")

    # ---- Python timings --------------------------------------------------------------------------
    seq = [qs[(k + 1) % 64] for k in range(args.reps)]
    fk, ufp = pin.forwardKinematics, pin.updateFramePlacement
    cfj, cjj, gfj = pin.computeFrameJacobian, pin.computeJointJacobians, pin.getFrameJacobian

    def run_loop(s):
        for q in s:
            pass

    def run_pose(s):
        for q in s:
            fk(model, data, q)
            ufp(model, data, flange)

    def run_pose_jac(s):
        for q in s:
            fk(model, data, q)
            ufp(model, data, flange)
            cfj(model, data, q, tool, lwa)[:3]

    def run_pose_jac_one_pass(s):
        for q in s:
            cjj(model, data, q)
            ufp(model, data, flange)
            gfj(model, data, tool, lwa)[:3]

    py_loop = best_per_call_ns(run_loop, seq, args.runs)
    py = {
        "flange_pose": best_per_call_ns(run_pose, seq, args.runs),
        "flange_pose_and_position_jacobian": best_per_call_ns(run_pose_jac, seq, args.runs),
        "flange_pose_and_position_jacobian_one_pass": best_per_call_ns(run_pose_jac_one_pass, seq, args.runs),
    }

    # ---- table -----------------------------------------------------------------------------------
    rc = {k: criterion_mean_ns(v) for k, v in CRITERION.items()}
    rc["flange_pose_and_position_jacobian_one_pass"] = rc["flange_pose_and_position_jacobian"]
    labels = {
        "flange_pose": "flange_pose",
        "flange_pose_and_position_jacobian": "flange_pose_and_position_jacobian",
        "flange_pose_and_position_jacobian_one_pass": "  same, Pinocchio one pass",
    }

    def fmt(v):
        return f"{v:.1f}" if v is not None else "n/a"

    def ratio(a, b):
        return f"{a / b:.2f}" if a is not None and b is not None else "n/a"

    rows = [("operation", "robocal (ns)", "Pinocchio Python (ns)", "Pinocchio C++ (ns)",
             "C++ / robocal", "Python / robocal")]
    for key, label in labels.items():
        c = cxx.get(key + "_ns")
        rows.append((label, fmt(rc[key]) if rc[key] is not None else "run cargo bench first",
                     fmt(py[key]), fmt(c), ratio(c, rc[key]), ratio(py[key], rc[key])))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    print(f"Pinocchio {pin.__version__} vs robocal, {os.path.relpath(os.path.abspath(args.urdf), REPO)} "
          f"-> {args.tip_link}, 64 configurations")
    for i, r in enumerate(rows):
        print(" | ".join(cell.ljust(w) if j == 0 else cell.rjust(w) for j, (cell, w) in enumerate(zip(r, widths))))
        if i == 0:
            print("-+-".join("-" * w for w in widths))
    print()
    print("robocal: criterion mean point estimate, target/criterion/<bench>/new/estimates.json")
    print(f"Pinocchio Python: best of {args.runs} runs of {args.reps} calls (time.perf_counter_ns); "
          f"the bare Python loop costs {py_loop:.1f} ns per iteration of that (included)")
    if cxx:
        print(f"Pinocchio C++: best of {cxx['runs']} runs of {cxx['reps']} calls (std::chrono::steady_clock), "
              f"wheel's libpinocchio_default.so, g++ -O3 -march=x86-64")
    else:
        print(f"Pinocchio C++: n/a: {cxx_note}")
    print("ratios: Pinocchio time / robocal time (> 1: robocal faster)")
    for c in checks:
        print("check OK: " + c)
    return 0


if __name__ == "__main__":
    sys.exit(main())
