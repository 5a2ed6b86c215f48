//! # robocal `calib`: identifying a robot's kinematic errors from laser-tracker measurements
//!
//! ## The model
//! The nominal robot ([`sim::Model`]) is the product of exponentials
//! `T_base_flange(q) = exp([S₁] q₁) ⋯ exp([Sₙ] qₙ) M`, screws `Sᵢ = [ωᵢ; vᵢ]` in the base frame at q = 0.
//! The real robot, as seen by a tracker, predicts the measured target (reflector) position
//!
//! ```text
//! p_tracker(q) = T_tracker_base · exp([S₁'](q₁ + δq₁)) ⋯ exp([Sₙ'](qₙ + δqₙ)) · M · p_flange
//! Sᵢ' = Ad(exp[ξᵢ]) Sᵢ                                    (adjoint error model)
//! R_tracker_target(q) = R_tracker_base · R(q) · R_M · R_flange_target   (6-DoF probes only)
//! ```
//!
//! with parameters ([`params`]): per joint an error twist `ξᵢ ∈ R⁶` (base frame; rad, m) that moves the
//! joint's axis by the rigid motion `exp[ξᵢ]`, and a zero offset `δqᵢ`; the tracker-to-base transform
//! (6 DoF); the target position `p_flange` (3; with orientation also `R_flange_target`, 3). A tool error
//! on `M` is absorbed by `p_flange` (and `R_flange_target`). Tracker-frame residuals are predicted minus
//! measured, divided by the row's standard deviation ([`problem::NoiseModel`]: the `sigma` column or a
//! laser-tracker default).
//!
//! ## Linearisation and the analytic Jacobian
//! The estimate is a point on a manifold, re-linearised after every step ([`params::KinematicParams::retract`]):
//! `Sᵢ' ← Ad(exp[Δξᵢ]) Sᵢ'`, `δqᵢ += Δδqᵢ`, `T_tracker_base ← exp([β]) T_tracker_base`,
//! `p_flange += Δp`, `R_flange_target ← R exp([ρ])`, and derivatives are always taken at `Δ = 0`.
//! Since `exp([Ad(g) S] θ) = g exp([S] θ) g⁻¹`, a step `Δξᵢ` turns `Eᵢ = exp([Sᵢ'] θᵢ)` into
//! `exp([Δξᵢ]) Eᵢ exp(−[Δξᵢ])`; with `Pᵢ = T_tracker_base E₁ ⋯ Eᵢ` this moves the target by the
//! tracker-frame twist `(Ad(Pᵢ₋₁) − Ad(Pᵢ)) Δξᵢ`, so
//!
//! ```text
//! ∂p/∂ξᵢ = A(Pᵢ₋₁) − A(Pᵢ),   A(R, t) = [ −[p − t] R ,  R ]          (3 × 6)
//! ∂p/∂δqᵢ = ωᵢ × (p − oᵢ)  (revolute; ωᵢ the current axis through oᵢ),   ωᵢ  (prismatic)
//! ∂p/∂β = [ −[p] , I ],   ∂p/∂p_flange = R_tracker_flange
//! ∂φ/∂ξᵢ = J_l⁻¹(φ) [Rᵢ₋₁ − Rᵢ , 0],   ∂φ/∂ρ = J_l⁻¹(φ) R_tracker_target   (φ = log(R_pred R_measᵀ))
//! ```
//!
//! ([`chain`]; checked against central differences in `tests/jacobian.rs`).
//!
//! ## Identifiability
//! Columns are scaled by the expected parameter magnitudes `D` ([`params::ParameterScales`]) and rows by
//! the noise; the SVD `J W^{1/2} D = U Σ Vᵀ` splits parameter space ([`lm::Subspace`]). Singular values
//! below `max(10⁻⁸ σ_max, 0.1)` are unidentifiable: the relative threshold catches the structural null
//! space (at rounding level, about 10⁻¹⁵ σ_max), the absolute one combinations whose standard deviation
//! would exceed ten times their expected magnitude. Steps are taken in the identifiable subspace only
//! (the minimum-norm step in scaled units), and the null space is named in parameter words
//! ([`identifiability`]): per revolute joint, the 2 error twists that leave its own axis unchanged; per
//! joint, the zero offset, equivalent to turning all later axes and the target about that joint's axis;
//! and 6 for the tracker-to-base transform against a common error twist of all axes. For `R` revolute and
//! `P` prismatic joints that leaves `4R + 2P + 3` identifiable combinations from positions (`+ 6` from full
//! poses), the classic count. Anything beyond is specific to the pose set (e.g. "joint 1 does not move")
//! and reported as such. Observability indices O1–O5 follow Sun and Hollerbach (ICRA 2008).
//!
//! ## Estimation
//! Weighted Levenberg–Marquardt ([`lm`], on any [`lm::LeastSquaresProblem`]) stops when no
//! Gauss–Newton step could lower `χ²` by more than a tiny amount (10⁻¹² in noise units, or 10⁻¹⁰ of `χ²`):
//! converged to the noise, not to an iteration count. Optional robust losses (Huber, Cauchy) work by
//! iterative reweighting. The covariance is `σ̂² D V_r Σ_r⁻² V_rᵀ D` with `σ̂² = χ²/(m − rank)` from the
//! residuals ([`calibrate`]). Only combinations in the identifiable subspace have meaningful standard
//! deviations; predictions always do (`J C Jᵀ`). Numerical trouble is counted, not hidden: every solver
//! report carries a [`health::Health`] record (non-finite residuals or Jacobian entries by row, overflow,
//! a near-singular normal matrix, the iteration and damping limits; [`health::Health::is_clean`]).
//!
//! ## End to end
//! ```
//! use calib::fit::{CalibrationOptions, Dataset, FitRequest, fit};
//! use sim::measurement_table::{MeasurementTable, OptionalColumns, Row};
//! use sim::{Data, flange_pose, robots};
//!
//! // A "real" UR5 whose joint 2 sits 0.5 mm off its nominal axis, measured by a tracker.
//! let model = robots::load_builtin("ur5").unwrap();
//! let mut origin = model.joints()[1].origin;
//! origin.translation.vector.x += 5e-4;
//! let real = model.with_joint_origin(1, origin).unwrap();
//! let mut data = Data::new(&real);
//! let mut table = MeasurementTable::new(6, OptionalColumns::NONE);
//! for k in 0..40 {
//!     let q: Vec<f64> = (0..6).map(|j| ((k * 7 + j * 3) as f64 * 0.618).sin() * 2.0).collect();
//!     let p = flange_pose(&real, &mut data, &q) * nalgebra::Point3::new(0.0, 0.03, 0.05);
//!     table.push_row(&Row { pose: k, q: &q, position: [p.x + 1.0, p.y, p.z], ..Row::default() }).unwrap();
//! }
//! let cal = fit(&model, &Dataset::all(&table, "example"), &FitRequest::kinematic(&CalibrationOptions::default())).unwrap();
//! assert!(cal.report.was_successful());
//! assert!(cal.report.before.train.max_m > 1e-4);   // the nominal model misses by 0.1 mm and more
//! assert!(cal.report.after.train.max_m < 1e-9);    // the calibrated one explains the data exactly
//! assert_eq!(cal.report.observability.rank, 4 * 6 + 3);
//! ```
#![warn(missing_docs)]

// The ground floor: numbers, errors and the solver, which know nothing of robots' causes.
pub mod cancel;
pub mod error;
pub mod health;
pub mod io;
pub mod lie3;
pub mod linalg;
pub mod lm;
pub mod part;
pub mod units;

// The four floors, each importing only from the floors below it (`scripts/check_floors.py`).
pub mod fit;
pub mod model;
pub mod select;
pub mod validate;

pub use error::{CalibError, Result};
pub use fit::{Calibration, CalibrationOptions, CalibrationReport, Dataset, FitRequest, fit};
pub use model::file::CalibratedModel;
pub use model::predict::Predictor;
