//! Subcommands, one module each; [`shared`] holds what several of them use. The error type that
//! decides the exit code is [`crate::error::CliError`]. The modules the Python package calls into
//! (`calibrate`, `diagnose`, `generate`, `predict`, `flags`, `shared`) are public: each keeps the
//! glue between reading its inputs and writing its outputs in functions of its own.

pub mod calibrate;
pub mod calibrate_stream;
pub mod compensate;
mod dataset;
mod demo;
pub mod diagnose;
mod fk;
pub mod flags;
pub mod generate;
mod info;
pub mod model_words;
mod paths;
pub mod plan_poses;
pub mod predict;
pub mod register;
pub mod robot_arg;
pub mod shared;
mod sweep;
mod urdf_out;

use crate::error::CliResult;
use clap::{Parser, Subcommand};

/// Simulate robot calibration campaigns with known errors, identify them, and diagnose what is left.
#[derive(Parser, Debug)]
#[command(name = "robocal", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Show a robot's chain: joints, axes, limits, masses.
    Info(info::Args),
    /// Flange pose at a joint configuration.
    Fk(fk::Args),
    /// Generate a measurement campaign with known injected errors (scenario file).
    Generate(generate::Args),
    /// Identify the error model from measurements.
    Calibrate(calibrate::Args),
    /// Predict target positions with a calibrated model.
    Predict(predict::Args),
    /// Compensated joint targets: the joints to command so that the calibrated robot puts the target
    /// where it should be (every cause inverted).
    Compensate(compensate::Args),
    /// Register a new measurement campaign (the tracker was moved) for a calibrated model.
    Register(register::Args),
    /// Choose the poses that determine the parameters best.
    PlanPoses(plan_poses::Args),
    /// Find what the kinematic model misses, name the cause, extend the model, measure the gain.
    Diagnose(diagnose::Args),
    /// The whole loop on the embedded iiwa 7: hide an effect, generate, calibrate, diagnose, compare.
    Demo(demo::Args),
    /// Sensitivity study: generate, calibrate and score runs over noise levels and pose counts.
    Sweep(sweep::Args),
    /// Join the shards of one sweep into the file a single run would have written.
    SweepMerge(sweep::MergeArgs),
    /// Write a versioned benchmark suite (train/test data, truth, SHA-256 manifest).
    Dataset(dataset::Args),
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> CliResult {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Fk(a) => fk::run(a),
        Command::Generate(a) => generate::run(a),
        Command::Calibrate(a) => calibrate::run(a),
        Command::Predict(a) => predict::run(a),
        Command::Compensate(a) => compensate::run(a),
        Command::Register(a) => register::run(a),
        Command::PlanPoses(a) => plan_poses::run(a),
        Command::Diagnose(a) => diagnose::run(a),
        Command::Demo(a) => demo::run(a),
        Command::Sweep(a) => sweep::run(a),
        Command::SweepMerge(a) => sweep::run_merge(a),
        Command::Dataset(a) => dataset::run(a),
    }
}
