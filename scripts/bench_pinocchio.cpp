// C++ half of scripts/bench_pinocchio.py: times Pinocchio's C++ API on the same iiwa 7 URDF and the same
// 64 joint configurations as sim/benches/kinematics.rs. Built and run by the Python script (it holds
// the g++ command line); not part of the cargo build.
//
// Usage: bench_pinocchio URDF TIP_LINK REPS RUNS
// Prints one JSON document on stdout: the best-of-RUNS time per call (ns, REPS calls per run, the
// configuration cycling through the 64 as in the criterion bench) for each timed operation, and the
// flange positions and tool-point position Jacobians of all 64 configurations for the correctness
// check done in Python.

#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

// Same role as std::hint::black_box in the Rust bench: the value must be materialised, and memory is
// treated as read and written, so nothing is hoisted out of the timing loop.
template <class T>
static inline void do_not_optimize(T const &value) {
  asm volatile("" : : "r,m"(value) : "memory");
}

int main(int argc, char **argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: %s URDF TIP_LINK REPS RUNS\n", argv[0]);
    return 2;
  }
  const std::string urdf = argv[1];
  const std::string tip = argv[2];
  const long reps = std::atol(argv[3]);
  const int runs = std::atoi(argv[4]);

  pinocchio::Model model;
  pinocchio::urdf::buildModel(urdf, model);
  const pinocchio::FrameIndex flange = model.getFrameId(tip);
  if (flange >= model.frames.size()) {
    std::fprintf(stderr, "no frame %s in %s\n", tip.c_str(), urdf.c_str());
    return 2;
  }
  // Tool point of the criterion bench: 0.05 m along the flange z axis, rigidly attached to the last joint.
  const pinocchio::Frame &ff = model.frames[flange];
  const pinocchio::SE3 tool_offset(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.0, 0.0, 0.05));
  const pinocchio::FrameIndex tool = model.addFrame(pinocchio::Frame(
      "robocal_tool", ff.parentJoint, flange, ff.placement * tool_offset, pinocchio::OP_FRAME));
  pinocchio::Data data(model);

  // q_k[i] = frac((k+1) * (0.618034 + 0.414214 i)) * 4 - 2, exactly as configs() in the Rust bench
  // (the argument is positive, so x - floor(x) is Rust's fract()).
  std::vector<Eigen::VectorXd> qs;
  for (int k = 0; k < 64; ++k) {
    Eigen::VectorXd q(model.nq);
    for (int i = 0; i < model.nq; ++i) {
      const double x = (double(k) + 1.0) * (0.618034 + 0.414214 * double(i));
      q[i] = (x - std::floor(x)) * 4.0 - 2.0;
    }
    qs.push_back(q);
  }

  pinocchio::Data::Matrix6x J = pinocchio::Data::Matrix6x::Zero(6, model.nv);

  auto time_op = [&](auto &&op) {
    double best = std::numeric_limits<double>::infinity();
    std::size_t k = 0;
    for (long r = 0; r < std::min<long>(reps / 10 + 1, 100000); ++r) {  // warm-up
      k = (k + 1) % qs.size();
      op(qs[k]);
    }
    for (int run = 0; run < runs; ++run) {
      const auto t0 = std::chrono::steady_clock::now();
      for (long r = 0; r < reps; ++r) {
        k = (k + 1) % qs.size();
        op(qs[k]);
      }
      const auto t1 = std::chrono::steady_clock::now();
      best = std::min(best, std::chrono::duration<double, std::nano>(t1 - t0).count() / double(reps));
    }
    return best;
  };

  // (1) flange pose.
  const double t_pose = time_op([&](const Eigen::VectorXd &q) {
    do_not_optimize(q.data());
    pinocchio::forwardKinematics(model, data, q);
    pinocchio::updateFramePlacement(model, data, flange);
    do_not_optimize(data.oMf[flange].translation()[0]);
  });
  // (2) flange pose + position Jacobian of the tool point (translation rows of the LOCAL_WORLD_ALIGNED
  // frame Jacobian = base-frame coordinates, reference point at the tool point).
  const double t_jac = time_op([&](const Eigen::VectorXd &q) {
    do_not_optimize(q.data());
    pinocchio::forwardKinematics(model, data, q);
    pinocchio::updateFramePlacement(model, data, flange);
    pinocchio::computeFrameJacobian(model, data, q, tool, pinocchio::LOCAL_WORLD_ALIGNED, J);
    do_not_optimize(data.oMf[flange].translation()[0]);
    do_not_optimize(J(0, 0));
  });
  // (2') the same result in one forward pass: computeJointJacobians (forward kinematics + all joint
  // Jacobians), then the flange placement and the tool-frame Jacobian read from data.J.
  const double t_jac_one_pass = time_op([&](const Eigen::VectorXd &q) {
    do_not_optimize(q.data());
    pinocchio::computeJointJacobians(model, data, q);
    pinocchio::updateFramePlacement(model, data, flange);
    pinocchio::getFrameJacobian(model, data, tool, pinocchio::LOCAL_WORLD_ALIGNED, J);
    do_not_optimize(data.oMf[flange].translation()[0]);
    do_not_optimize(J(0, 0));
  });

  std::printf("{\n  \"reps\": %ld,\n  \"runs\": %d,\n", reps, runs);
  std::printf("  \"flange_pose_ns\": %.6f,\n", t_pose);
  std::printf("  \"flange_pose_and_position_jacobian_ns\": %.6f,\n", t_jac);
  std::printf("  \"flange_pose_and_position_jacobian_one_pass_ns\": %.6f,\n", t_jac_one_pass);
  std::printf("  \"q\": [");
  for (std::size_t k = 0; k < qs.size(); ++k) {
    std::printf("%s[", k ? ", " : "");
    for (int i = 0; i < model.nq; ++i) std::printf("%s%.17g", i ? ", " : "", qs[k][i]);
    std::printf("]");
  }
  std::printf("],\n  \"flange_position\": [");
  for (std::size_t k = 0; k < qs.size(); ++k) {
    pinocchio::forwardKinematics(model, data, qs[k]);
    pinocchio::updateFramePlacement(model, data, flange);
    const Eigen::Vector3d p = data.oMf[flange].translation();
    std::printf("%s[%.17g, %.17g, %.17g]", k ? ", " : "", p[0], p[1], p[2]);
  }
  std::printf("],\n  \"tool_position_jacobian\": [");
  for (std::size_t k = 0; k < qs.size(); ++k) {
    J.setZero();
    pinocchio::computeFrameJacobian(model, data, qs[k], tool, pinocchio::LOCAL_WORLD_ALIGNED, J);
    std::printf("%s[", k ? ", " : "");
    for (int r = 0; r < 3; ++r) {
      std::printf("%s[", r ? ", " : "");
      for (int c = 0; c < model.nv; ++c) std::printf("%s%.17g", c ? ", " : "", J(r, c));
      std::printf("]");
    }
    std::printf("]");
  }
  std::printf("]\n}\n");
  return 0;
}
