//! What each candidate pose would tell the fit of a model: its weighted Jacobian rows, at the nominal
//! robot, with respect to every parameter of the model (kinematic, tracker and target, and every
//! cause's), projected onto the directions the whole candidate set identifies.
//!
//! The rows are the fit's own: the candidates become a measurement table (positions at the nominal
//! target, so that a distance-dependent noise model weighs them as it would weigh the measurements),
//! the causes configure themselves on it as on training data ([`ExtensionSettings::for_data`]), and
//! the Jacobian is [`KinematicProblem`]'s at zero errors, where the causes' regressors are evaluated
//! at the nominal equilibrium (gravity torques of the nominal robot with each candidate's payload).

use super::PlanOptions;
use crate::error::{CalibError, Result};
use crate::fit::problem::KinematicProblem;
use crate::fit::{Dataset, observations};
use crate::lm::{LeastSquaresProblem, Subspace};
use crate::model::extensions::ExtensionSettings;
use crate::model::params::{KinematicParams, ParamLayout};
use nalgebra::{DMatrix, DVector, Point3};
use sim::Model;
use sim::lie::Pose;
use sim::measurement_table::MeasurementTable;

/// The candidates' information about a model (see the module docs).
pub(super) struct CandidateInformation {
    /// `Aₖ` per candidate row (3 × r): weighted Jacobian rows times [`Self::basis`].
    pub blocks: Vec<DMatrix<f64>>,
    /// Identifiable combinations of the candidate set `r`.
    pub rank: usize,
    /// `B = D Vᵣ` (p × r): the physical parameter step of a unit step along each identifiable
    /// direction of the scaled parameter space.
    pub basis: DMatrix<f64>,
    /// The parameters.
    pub layout: ParamLayout,
    /// The weighted Jacobian of every candidate row (3n × p, physical units).
    pub jacobian: DMatrix<f64>,
    /// The column scales `D` (expected parameter magnitudes).
    pub scales: DVector<f64>,
    /// Whether each parameter alone is determined by the candidate set (its functional sees no
    /// direction of the null space, as in the calibration report).
    pub determined: Vec<bool>,
    /// Position standard deviation of each candidate row (m), from the noise model.
    pub sigma_m: Vec<f64>,
}

/// `T_tracker_base` of a tracker standing at `tracker` (base frame, m) with its axes along the
/// base's: the identity without one.
pub(super) fn tracker_pose(tracker: Option<&nalgebra::Vector3<f64>>) -> Pose {
    match tracker {
        Some(t) => Pose::translation(-t.x, -t.y, -t.z),
        None => Pose::identity(),
    }
}

/// Puts the nominal target position in the tracker frame into every row of `table`.
pub(super) fn place_targets(model: &Model, table: &mut MeasurementTable, options: &PlanOptions) {
    let mut data = sim::kinematics::Data::new(model);
    let t_tracker_base = tracker_pose(options.constraints.tracker_base_m.as_ref());
    for r in 0..table.len() {
        let q = table.q_row(r).to_vec();
        sim::kinematics::forward_kinematics(model, &mut data, &q);
        let p = t_tracker_base * (data.flange * Point3::from(options.target_offset));
        table.position[r] = [p.x, p.y, p.z];
    }
}

/// The information of every row of `table` (candidates with their targets placed,
/// [`place_targets`]) about `options.model`.
pub(super) fn candidate_information(
    model: &Model,
    table: &MeasurementTable,
    options: &PlanOptions,
) -> Result<CandidateInformation> {
    let source = "plan-poses candidates";
    let data = Dataset::all(table, source);
    let spec = &options.model;
    let settings = if spec.causes.is_empty() {
        None
    } else {
        let mut s = ExtensionSettings::for_data(
            model,
            &spec.causes,
            &spec.joints,
            table,
            &data.rows,
            source,
        )?;
        s.payload_com_m = options.payload_com_m.into();
        Some(s)
    };
    let n_ext = settings.as_ref().map_or(0, |s| s.params(model).len());
    let mut calibration = options.calibration;
    calibration.noise = options.noise;
    let obs = observations(model, &data, &calibration, settings.as_ref(), None)?;
    let mut start = KinematicParams::nominal(model.nq(), false);
    start.p_flange_target = options.target_offset;
    start.t_tracker_base = tracker_pose(options.constraints.tracker_base_m.as_ref());
    start.extension = vec![0.0; n_ext];
    let p = ParamLayout::for_params(model, &start, obs.ext.params.clone()).len();
    let mut prob = KinematicProblem::new(model, &obs, start, (0..p).collect());
    let m = prob.n_residuals();
    prob.set_params(&vec![0.0; p]);
    let mut r0 = vec![0.0; m];
    prob.residuals(&mut r0);
    let mut jacobian = DMatrix::zeros(m, p);
    prob.jacobian(&mut jacobian);
    let layout = prob.layout().clone();
    let scales = calibration.scales.vector(&layout);
    let sub = Subspace::analyze(
        &jacobian,
        scales.as_slice(),
        calibration.lm.rank_rtol,
        calibration.lm.min_singular_value,
    );
    let rank = sub.rank;
    if rank == 0 {
        return Err(CalibError::BadValue {
            context: "plan-poses".into(),
            field: "candidates".into(),
            value: table.len().to_string(),
            problem: "the candidates determine no parameter combination".into(),
        });
    }
    let mut basis = sub.v.columns(0, rank).into_owned();
    for (row, d) in scales.iter().enumerate() {
        basis.row_mut(row).scale_mut(*d);
    }
    let dim = m / table.len();
    let blocks = (0..table.len())
        .map(|c| jacobian.rows(dim * c, dim) * &basis)
        .collect();
    let null = sub.v.columns(rank, p - rank);
    let determined = (0..p)
        .map(|k| null.row(k).norm() <= 1e-6)
        .collect::<Vec<bool>>();
    Ok(CandidateInformation {
        blocks,
        rank,
        basis,
        layout,
        jacobian,
        scales,
        determined,
        sigma_m: obs.sigma.clone(),
    })
}
