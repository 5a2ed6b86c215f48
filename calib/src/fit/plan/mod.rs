//! Choosing measurement poses: optimal experiment design for any model from candidates drawn or given.
//!
//! Candidates are configurations drawn uniformly within the joint limits less a margin (±π for joints
//! without limits) from `StdRng::seed_from_u64(seed)`, or the user's own (`--candidates-file`). With
//! payload masses to choose from, every configuration is a candidate once per mass. Candidates that
//! break a constraint of the cell ([`constraints`]: tracker range and line of sight, floor, joint
//! margins) are counted per constraint and left out.
//!
//! Each candidate's weighted Jacobian rows of the model to be fitted (kinematic, tracker and target,
//! and every cause's parameters, [`information`]), scaled by the expected parameter magnitudes, are
//! projected onto the identifiable subspace of the whole candidate set (`Aₖ = Jₖ B`, 3 × r). The
//! selection maximises the D-, A- or E-optimal criterion of `Σₖ∈S Aₖᵀ Aₖ` ([`design`]): greedy, then
//! exchange passes. It is compared with random subsets of the same candidates (the same size, payloads
//! drawn with them). Collisions of the robot with itself and cable routing are not considered.

pub mod constraints;
pub mod design;
mod information;

pub use constraints::{CellConstraints, Constraint};
pub use design::Criterion;

use crate::error::{CalibError, Result};
use crate::fit::CalibrationOptions;
use crate::fit::identifiability::Observability;
use crate::lm::Subspace;
use crate::model::observations::NoiseModel;
use crate::model::spec::ModelSpec;
use crate::units::Unit;
use nalgebra::{DMatrix, Vector3};
use rand::{RngExt, SeedableRng};
use sim::Model;
use sim::measurement_table::{MeasurementTable, OptionalColumns};

/// Most candidate rows (configurations × payloads, after the constraints) a plan takes: the
/// candidates' Jacobian rows and blocks take about 2.5 kB a row for the iiwa 7 with compliance
/// (250 MB at this limit). More are refused with the count; a random subset of the robot's poses
/// serves as well (the design picks a few dozen of them).
pub const MAX_CANDIDATE_ROWS: usize = 100_000;

/// Settings of [`plan`] and [`plan_poses`].
#[derive(Clone, Debug, PartialEq)]
pub struct PlanOptions {
    /// Number of random candidate configurations `N` ([`plan_poses`]).
    pub candidates: usize,
    /// Number of poses to select `K`.
    pub select: usize,
    /// Seed of the candidate draw and of the random comparison sets.
    pub seed: u64,
    /// The model whose parameters the poses should determine. Default: the kinematic model.
    pub model: ModelSpec,
    /// The design criterion. Default D-optimal.
    pub criterion: Criterion,
    /// Payload masses (kg) each pose may carry; empty: the candidates' own (none when they have no
    /// `payload` column).
    pub payloads_kg: Vec<f64>,
    /// The payload's centre of mass in the flange frame (m). Default at the flange origin.
    pub payload_com_m: Vector3<f64>,
    /// Target position in the flange frame (m) assumed for planning. Default (0.05, 0.03, 0.08): a
    /// reflector off the flange axes (one on the last joint's axis hides that axis's position).
    pub target_offset: Vector3<f64>,
    /// The tracker's noise (m, and m per m of distance from the tracker). Default 1e-5 m, constant.
    pub noise: NoiseModel,
    /// The cell's constraints. Default none.
    pub constraints: CellConstraints,
    /// Calibration settings (parameter scales, rank threshold).
    pub calibration: CalibrationOptions,
    /// Random K-subsets drawn for the comparison. Default 50.
    pub random_sets: usize,
    /// Maximum exchange passes after the greedy selection. Default 4.
    pub exchange_passes: usize,
    /// Keep every candidate's information block in the plan ([`PosePlan::information_csv`]), for
    /// comparing other designs on the same candidates. Default false.
    pub keep_information: bool,
}

impl PlanOptions {
    /// Defaults for `candidates` and `select`.
    pub fn new(candidates: usize, select: usize, seed: u64) -> Self {
        PlanOptions {
            candidates,
            select,
            seed,
            model: ModelSpec::kinematic(),
            criterion: Criterion::D,
            payloads_kg: Vec::new(),
            payload_com_m: Vector3::zeros(),
            target_offset: Vector3::new(0.05, 0.03, 0.08),
            noise: NoiseModel {
                position_sigma_m: 1e-5,
                position_sigma_per_m: 0.0,
                ..NoiseModel::default()
            },
            constraints: CellConstraints::default(),
            calibration: CalibrationOptions::default(),
            random_sets: 50,
            exchange_passes: 4,
            keep_information: false,
        }
    }
}

/// Candidate poses: one row each (pose id = row), with the context columns they came with (`payload`,
/// `temp`, `t`, `dir1..dirN`); positions are filled by the planner.
#[derive(Clone, Debug, PartialEq)]
pub struct Candidates {
    /// The candidates.
    pub table: MeasurementTable,
    /// Each candidate's pose id in its source (the draw's index, or the file's `pose`).
    pub source_pose: Vec<i64>,
    /// Where they come from, for messages.
    pub source: String,
}

impl Candidates {
    /// `n` configurations drawn uniformly within the joint limits less `constraints.joint_margin`
    /// (±π for joints without limits), from `StdRng::seed_from_u64(seed)`.
    pub fn drawn(
        model: &Model,
        n: usize,
        seed: u64,
        constraints: &CellConstraints,
    ) -> Result<Self> {
        let range = constraints
            .drawable_range(model)
            .ok_or_else(|| CalibError::BadValue {
                context: "plan-poses".into(),
                field: "--joint-margin".into(),
                value: constraints.joint_margin.to_string(),
                problem: "leaves no range to draw from at some joint".into(),
            })?;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let configs: Vec<Vec<f64>> = (0..n).map(|_| random_q(&range, &mut rng)).collect();
        Ok(Self::from_configurations(
            model,
            &configs,
            "drawn candidates",
        ))
    }

    /// The given configurations (rad or m), in order.
    pub fn from_configurations(model: &Model, configs: &[Vec<f64>], source: &str) -> Self {
        let mut table =
            MeasurementTable::with_capacity(model.nq(), OptionalColumns::NONE, configs.len());
        for (k, q) in configs.iter().enumerate() {
            table.pose.push(k as i64);
            table.q.extend_from_slice(q);
            table.position.push([0.0; 3]);
        }
        Candidates {
            table,
            source_pose: (0..configs.len() as i64).collect(),
            source: source.to_string(),
        }
    }

    /// The poses of a table of configurations (`pose, q1..qN` and context columns, as
    /// [`sim::measurement_table::read_configurations`] reads them): each pose's first row.
    pub fn from_table(model: &Model, table: &MeasurementTable, source: &str) -> Result<Self> {
        if table.n_joints != model.nq() {
            return Err(CalibError::BadValue {
                context: source.to_string(),
                field: "q1..qN".into(),
                value: format!("{} joint columns", table.n_joints),
                problem: format!("robot '{}' has {} joints", model.name(), model.nq()),
            });
        }
        let by_pose = table.rows_by_pose();
        let first: Vec<usize> = by_pose.iter().map(|(_, rows)| rows[0]).collect();
        let mut picked = table.select_rows(&first);
        picked.orientation = None;
        picked.sigma = None;
        picked.campaign = None;
        picked.pose = (0..picked.len() as i64).collect();
        Ok(Candidates {
            table: picked,
            source_pose: by_pose.iter().map(|(p, _)| *p).collect(),
            source: source.to_string(),
        })
    }

    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.table.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }
}

/// Candidates a constraint left out.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Rejected {
    /// The constraint (the first one a candidate breaks, in [`Constraint::ALL`] order).
    pub constraint: Constraint,
    /// How many candidate configurations broke it.
    pub count: usize,
    /// The first few of them (pose ids of the candidates' source; at most ten).
    pub first_poses: Vec<i64>,
}

/// A parameter's predicted standard deviation.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PlannedParameter {
    /// Its name, as in the calibration report and the model file.
    pub name: String,
    /// Its unit.
    pub unit: Unit,
    /// Predicted standard deviation after calibrating on the selection, `None` when the candidates
    /// do not determine the parameter on its own.
    pub sigma: Option<f64>,
    /// The same for the median random subset.
    pub random_sigma: Option<f64>,
}

/// The selected poses and how much better they are than random ones.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PosePlan {
    /// The model planned for (its canonical name).
    pub model: String,
    /// The criterion.
    pub criterion: Criterion,
    /// Candidate configurations considered, after the constraints.
    pub candidates: usize,
    /// Candidate configurations each constraint left out.
    pub rejected: Vec<Rejected>,
    /// Joint values of the selected poses (rad or m), in selection order.
    pub selected: Vec<Vec<f64>>,
    /// Payload mass of each selected pose (kg), when the candidates carry payloads.
    pub payload_kg: Option<Vec<f64>>,
    /// The selected poses' ids in the candidates' source.
    pub source_poses: Vec<i64>,
    /// Their indices among the candidate rows (configurations × payloads, after the constraints).
    pub candidate_indices: Vec<usize>,
    /// Identifiable combinations of the candidate set.
    pub rank: usize,
    /// Parameters of the model.
    pub n_params: usize,
    /// The criterion's value for the selection ([`Criterion::value`]).
    pub criterion_value: f64,
    /// Its median over the random subsets (non-singular ones).
    pub random_criterion_median: f64,
    /// `log det` of the scaled information of the selection (identifiable subspace).
    pub log_det: f64,
    /// Mean `log det` of random K-subsets of the candidates (non-singular ones).
    pub random_log_det_mean: f64,
    /// Standard deviation of that over the random subsets.
    pub random_log_det_std: f64,
    /// Random subsets whose information was singular (left out of the mean).
    pub random_singular: usize,
    /// `exp((log det_random − log det_selected) / (2 r))`: how many times larger the geometric-mean
    /// parameter standard deviation of random poses is.
    pub parameter_sigma_ratio: f64,
    /// Predicted held-out error against the truth: the RMS over all candidates of the predicted
    /// position's standard deviation (m, the root of the trace of its 3 × 3 covariance) after
    /// calibrating on the selection.
    pub position_sigma_m: f64,
    /// The same for the median random subset.
    pub random_position_sigma_m: f64,
    /// Predicted RMS held-out residual against measurements (m): `position_sigma_m` and the tracker
    /// noise of the candidates, `√(position_sigma_m² + mean 3σᵢ²)`.
    pub predicted_heldout_rms_m: f64,
    /// Every parameter's predicted standard deviation.
    pub parameters: Vec<PlannedParameter>,
    /// Observability indices of the selection.
    pub observability: Observability,
    /// The selected rows (pose ids 0..K) with their context columns, for [`PosePlan::to_csv`].
    #[serde(skip)]
    table: MeasurementTable,
    /// With [`PlanOptions::keep_information`], every candidate row and its block `Aₖ` (3 × r).
    #[serde(skip)]
    information: Option<(MeasurementTable, Vec<DMatrix<f64>>)>,
}

fn random_q(range: &[(f64, f64)], rng: &mut rand::rngs::StdRng) -> Vec<f64> {
    range
        .iter()
        .map(|(lo, hi)| lo + (hi - lo) * rng.random::<f64>())
        .collect()
}

fn bad(field: &str, value: String, problem: String) -> CalibError {
    CalibError::BadValue {
        context: "plan-poses".into(),
        field: field.into(),
        value,
        problem,
    }
}

/// Checks the settings that do not depend on the candidates.
fn check_options(options: &PlanOptions) -> Result<()> {
    if options.select == 0 {
        return Err(bad(
            "--select",
            "0".into(),
            "select at least one pose".into(),
        ));
    }
    let n = &options.noise;
    if !(n.position_sigma_m.is_finite()
        && n.position_sigma_per_m.is_finite()
        && n.position_sigma_m >= 0.0
        && n.position_sigma_per_m >= 0.0
        && n.position_sigma_m + n.position_sigma_per_m > 0.0)
    {
        return Err(bad(
            "--noise",
            format!("{:?}", n.position_sigma_m),
            "must be > 0 m".into(),
        ));
    }
    if let Some(kind) = options.model.learned {
        return Err(bad(
            "--model",
            options.model.name(),
            format!(
                "a learned correction (learned:{}) has no parameters to plan poses for: plan for the \
                 causes, and measure the learned correction's region densely",
                kind.name()
            ),
        ));
    }
    if let Some(m) = options
        .payloads_kg
        .iter()
        .find(|m| !(m.is_finite() && **m >= 0.0))
    {
        return Err(bad(
            "--payloads",
            m.to_string(),
            "payload masses must be ≥ 0 kg".into(),
        ));
    }
    if !options.payload_com_m.iter().all(|v| v.is_finite()) {
        return Err(bad(
            "--payload-com",
            format!("{:?}", options.payload_com_m),
            "must be finite (m)".into(),
        ));
    }
    options.constraints.validate()
}

/// The candidates that keep every constraint, and what the others broke.
fn constrained(
    model: &Model,
    candidates: &Candidates,
    options: &PlanOptions,
) -> (Vec<usize>, Vec<Rejected>) {
    let mut data = sim::kinematics::Data::new(model);
    let mut kept = Vec::with_capacity(candidates.len());
    let mut rejected: Vec<Rejected> = Vec::new();
    for r in 0..candidates.len() {
        match options.constraints.broken(
            model,
            &mut data,
            candidates.table.q_row(r),
            &options.target_offset,
        ) {
            None => kept.push(r),
            Some(c) => {
                let entry = match rejected.iter().position(|x| x.constraint == c) {
                    Some(i) => &mut rejected[i],
                    None => {
                        rejected.push(Rejected {
                            constraint: c,
                            count: 0,
                            first_poses: Vec::new(),
                        });
                        rejected.last_mut().expect("just pushed")
                    }
                };
                entry.count += 1;
                if entry.first_poses.len() < 10 {
                    entry.first_poses.push(candidates.source_pose[r]);
                }
            }
        }
    }
    rejected.sort_by_key(|x| x.constraint);
    (kept, rejected)
}

/// The candidate rows: `kept` of `candidates`, each once per payload of `options.payloads_kg` (in that
/// order within a configuration), pose id = row. Returns the table and each row's candidate index.
fn candidate_rows(
    candidates: &Candidates,
    kept: &[usize],
    options: &PlanOptions,
) -> Result<(MeasurementTable, Vec<usize>)> {
    let table = candidates.table.select_rows(kept);
    if options.payloads_kg.is_empty() {
        let mut t = table;
        t.pose = (0..t.len() as i64).collect();
        return Ok((t, kept.to_vec()));
    }
    if table.payload.is_some() {
        return Err(bad(
            "--payloads",
            format!("{:?}", options.payloads_kg),
            format!(
                "{} has its own payload column: leave out --payloads, or the column",
                candidates.source
            ),
        ));
    }
    let n = table.len() * options.payloads_kg.len();
    let mut out = table.empty_like(n);
    out.payload = Some(Vec::with_capacity(n));
    let mut index = Vec::with_capacity(n);
    for (r, &k) in kept.iter().enumerate() {
        for &m in &options.payloads_kg {
            let mut row = table.row(r);
            row.pose = out.len() as i64;
            row.payload = Some(m);
            out.push_row(&row)?;
            index.push(k);
        }
    }
    Ok((out, index))
}

/// `G = Σₖ σₖ² Aₖᵀ Aₖ / n` over the candidates (`sigma` their noise, m, by which their blocks were
/// weighted): the mean covariance map of a predicted position, so that its mean variance for the
/// inverse information `P` is `tr(P G)` ([`rms_position_sigma`]).
fn position_map(a: &[DMatrix<f64>], sigma: &[f64], r: usize) -> DMatrix<f64> {
    let mut g = DMatrix::zeros(r, r);
    for (ak, s) in a.iter().zip(sigma) {
        g.gemm_tr(s * s / a.len() as f64, ak, ak, 1.0);
    }
    g
}

/// RMS over the candidates of the predicted position's standard deviation (m, the root of the trace
/// of its 3 × 3 covariance) for the inverse information `pinv`: `√tr(P G)`.
fn rms_position_sigma(g: &DMatrix<f64>, pinv: &DMatrix<f64>) -> f64 {
    pinv.component_mul(g).sum().max(0.0).sqrt()
}

/// Every determined parameter's standard deviation (physical units) for the inverse information
/// `pinv` in the identifiable coordinates: the diagonal of `B P Bᵀ`.
fn parameter_sigmas(
    basis: &DMatrix<f64>,
    pinv: &DMatrix<f64>,
    determined: &[bool],
) -> Vec<Option<f64>> {
    let bp = basis * pinv;
    (0..basis.nrows())
        .map(|k| determined[k].then(|| bp.row(k).dot(&basis.row(k)).max(0.0).sqrt()))
        .collect()
}

/// Selects `options.select` of `candidates` for calibrating `options.model` (see the module docs):
/// the constraints first, then every remaining configuration once per payload, then the design.
pub fn plan(model: &Model, candidates: &Candidates, options: &PlanOptions) -> Result<PosePlan> {
    check_options(options)?;
    let (kept, rejected) = constrained(model, candidates, options);
    let k = options.select;
    if kept.is_empty() {
        let broken: Vec<String> = rejected
            .iter()
            .map(|r| format!("{} {}", r.count, r.constraint.name()))
            .collect();
        return Err(bad(
            "candidates",
            candidates.len().to_string(),
            format!(
                "no candidate of {} keeps the constraints ({})",
                candidates.source,
                broken.join(", ")
            ),
        ));
    }
    let rows = kept.len() * options.payloads_kg.len().max(1);
    if rows > MAX_CANDIDATE_ROWS {
        return Err(bad(
            "candidates",
            rows.to_string(),
            format!(
                "{} configurations{} are more than the {MAX_CANDIDATE_ROWS} candidates a plan takes: \
                 draw fewer (--candidates), or give a random subset of {}",
                kept.len(),
                if options.payloads_kg.len() > 1 {
                    format!(" × {} payloads", options.payloads_kg.len())
                } else {
                    String::new()
                },
                candidates.source
            ),
        ));
    }
    let (mut table, config_of_row) = candidate_rows(candidates, &kept, options)?;
    if table.len() < k {
        return Err(bad(
            "--select",
            k.to_string(),
            format!(
                "only {} candidates keep the constraints ({} from {})",
                table.len(),
                kept.len(),
                candidates.source
            ),
        ));
    }
    information::place_targets(model, &mut table, options);
    let info = information::candidate_information(model, &table, options)?;
    let (a, r) = (&info.blocks, info.rank);
    if 3 * k < r + 1 {
        return Err(bad(
            "--select",
            k.to_string(),
            format!(
                "{r} parameter combinations are identifiable: select at least {} poses (3 equations each, \
                 one more than the parameters)",
                (r + 1).div_ceil(3)
            ),
        ));
    }
    let (set, criterion_value) =
        design::choose(a, r, k, options.criterion, options.exchange_passes);
    let pinv = design::inverse_information(a, &set, r).ok_or_else(|| {
        bad(
            "candidates",
            table.len().to_string(),
            "the candidates cannot determine the identifiable parameters together; draw more"
                .into(),
        )
    })?;
    let log_det_selected = Criterion::D
        .value(&design::information(a, &set, r))
        .unwrap_or(f64::NEG_INFINITY);
    let g = position_map(a, &info.sigma_m, r);
    let position_sigma_m = rms_position_sigma(&g, &pinv);
    let sigmas = parameter_sigmas(&info.basis, &pinv, &info.determined);

    // Random subsets of the same size.
    let n = a.len();
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed ^ 0x005e_ed0f_7a4d);
    let (mut logs, mut values, mut position, mut per_param) = (
        Vec::new(),
        Vec::new(),
        Vec::new(),
        vec![Vec::new(); info.determined.len()],
    );
    let mut singular = 0;
    for _ in 0..options.random_sets {
        let mut idx: Vec<usize> = (0..n).collect();
        for i in 0..k {
            let j = i + (rng.random::<f64>() * (n - i) as f64) as usize;
            idx.swap(i, j.min(n - 1));
        }
        let subset = &idx[..k];
        let m = design::information(a, subset, r);
        match (Criterion::D.value(&m), m.clone().cholesky()) {
            (Some(v), Some(c)) => {
                let pi = c.inverse();
                logs.push(v);
                values.extend(options.criterion.value(&m));
                position.push(rms_position_sigma(&g, &pi));
                for (p, s) in
                    per_param
                        .iter_mut()
                        .zip(parameter_sigmas(&info.basis, &pi, &info.determined))
                {
                    p.extend(s);
                }
            }
            _ => singular += 1,
        }
    }
    let median = |v: &mut Vec<f64>| -> Option<f64> {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let mean = logs.iter().sum::<f64>() / logs.len().max(1) as f64;
    let std = (logs.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>()
        / logs.len().max(1) as f64)
        .sqrt();

    // Observability of the selection (same scaling as calibrate).
    let p = info.layout.len();
    let mut jsel = DMatrix::zeros(3 * k, p);
    for (i, &c) in set.iter().enumerate() {
        jsel.rows_mut(3 * i, 3)
            .copy_from(&info.jacobian.rows(3 * c, 3));
    }
    let observability = Observability::from_subspace(&Subspace::analyze(
        &jsel,
        info.scales.as_slice(),
        options.calibration.lm.rank_rtol,
        options.calibration.lm.min_singular_value,
    ));
    let mean_noise = info.sigma_m.iter().map(|s| 3.0 * s * s).sum::<f64>() / n as f64;
    let parameters = (0..p)
        .map(|i| PlannedParameter {
            name: info.layout.name(i),
            unit: info.layout.unit(i),
            sigma: sigmas[i],
            random_sigma: median(&mut per_param[i]),
        })
        .collect();
    let mut selection = table.select_rows(&set);
    selection.pose = (0..k as i64).collect();
    Ok(PosePlan {
        model: options.model.name(),
        criterion: options.criterion,
        candidates: kept.len(),
        rejected,
        selected: set.iter().map(|&c| table.q_row(c).to_vec()).collect(),
        payload_kg: selection.payload.clone(),
        source_poses: set
            .iter()
            .map(|&c| candidates.source_pose[config_of_row[c]])
            .collect(),
        candidate_indices: set,
        rank: r,
        n_params: p,
        criterion_value,
        random_criterion_median: median(&mut values).unwrap_or(f64::NAN),
        log_det: log_det_selected,
        random_log_det_mean: mean,
        random_log_det_std: std,
        random_singular: singular,
        parameter_sigma_ratio: if logs.is_empty() {
            f64::INFINITY
        } else {
            ((log_det_selected - mean) / (2.0 * r as f64)).exp()
        },
        position_sigma_m,
        random_position_sigma_m: median(&mut position).unwrap_or(f64::INFINITY),
        predicted_heldout_rms_m: (position_sigma_m * position_sigma_m + mean_noise).sqrt(),
        parameters,
        observability,
        table: selection,
        information: options
            .keep_information
            .then(|| (table.clone(), info.blocks.clone())),
    })
}

/// Selects `options.select` poses of `options.candidates` random ones ([`Candidates::drawn`]) for
/// calibrating `options.model`.
pub fn plan_poses(model: &Model, options: &PlanOptions) -> Result<PosePlan> {
    check_options(options)?;
    if options.candidates < options.select {
        return Err(bad(
            "--candidates",
            options.candidates.to_string(),
            format!("fewer candidates than poses to select ({})", options.select),
        ));
    }
    let candidates = Candidates::drawn(
        model,
        options.candidates,
        options.seed,
        &options.constraints,
    )?;
    plan(model, &candidates, options)
}

impl PosePlan {
    /// With [`PlanOptions::keep_information`], CSV text of every candidate's information about the
    /// identifiable combinations: `candidate, q1..qN, payload, coordinate, a1..ar`, three rows per
    /// candidate (`coordinate` 0, 1, 2 for x, y, z), where `a` is the candidate's weighted, scaled
    /// Jacobian row projected on the `r` identifiable directions of the candidate set, so that
    /// `Σₖ∈S Aₖᵀ Aₖ` is the information of a selection `S` (dimensionless); `candidate` numbers the
    /// rows as [`PosePlan::candidate_indices`] does. `None` without the option.
    pub fn information_csv(&self) -> Option<String> {
        let (t, blocks) = self.information.as_ref()?;
        let nq = t.n_joints;
        let r = blocks.first().map_or(0, DMatrix::ncols);
        let mut header = vec!["candidate".to_string()];
        header.extend((1..=nq).map(|j| format!("q{j}")));
        header.push("payload".into());
        header.push("coordinate".into());
        header.extend((1..=r).map(|k| format!("a{k}")));
        let mut s = header.join(",");
        s.push('\n');
        for (c, b) in blocks.iter().enumerate() {
            for i in 0..3 {
                s.push_str(&c.to_string());
                for v in t.q_row(c) {
                    s.push_str(&format!(",{v:?}"));
                }
                s.push_str(&format!(",{:?},{i}", t.payload_or_zero(c)));
                for v in b.row(i).iter() {
                    s.push_str(&format!(",{v:?}"));
                }
                s.push('\n');
            }
        }
        Some(s)
    }

    /// CSV text of the selected poses (pose ids 0..K): `pose, q1..qN`, then the context columns the
    /// candidates carried or the plan chose: `payload` (kg), `temp` (°C), `t` (s), `dir1..dirN`. It is
    /// a pose file for `generate`'s `[campaign.file]` and for `predict`.
    pub fn to_csv(&self) -> String {
        let t = &self.table;
        let nq = t.n_joints;
        let mut header = vec!["pose".to_string()];
        header.extend((1..=nq).map(|j| format!("q{j}")));
        let named = [("payload", &t.payload), ("temp", &t.temp), ("t", &t.t)];
        header.extend(
            named
                .iter()
                .filter(|(_, c)| c.is_some())
                .map(|(n, _)| n.to_string()),
        );
        if t.dir.is_some() {
            header.extend((1..=nq).map(|j| format!("dir{j}")));
        }
        let mut s = header.join(",");
        s.push('\n');
        for r in 0..t.len() {
            s.push_str(&t.pose[r].to_string());
            for v in t.q_row(r) {
                s.push_str(&format!(",{v:?}"));
            }
            for (_, c) in named.iter() {
                if let Some(c) = c {
                    s.push_str(&format!(",{:?}", c[r]));
                }
            }
            if let Some(d) = t.dir_row(r) {
                for v in d {
                    s.push_str(&format!(",{v}"));
                }
            }
            s.push('\n');
        }
        s
    }
}
