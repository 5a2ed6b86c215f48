//! A run's scores against the truth: held-out errors, the identifiable combinations in units of
//! their predicted σ, and each extension parameter's error in units of its σ.
//!
//! Predictions go through calib's one prediction path ([`Prediction`], the extensions' regressors
//! built as `robocal predict` builds them, the learned correction added); Jacobians through
//! [`position_jacobian_row`] (extension columns included). The learned correction has no covariance:
//! the predicted error and the combinations are the physical model's.

use super::params_table::ParamRow;
use super::truth_params::truth_of;
use calib::fit::Calibration;
use calib::model::extensions::{Cause, Regressors};
use calib::model::jacobian::position_jacobian_row;
use calib::model::params::KinematicParams;
use calib::model::predict::Prediction;
use nalgebra::{DMatrix, DVector, Vector3};
use sim::measurement_table::MeasurementTable;

/// A parameter whose scaled direction has more than this share in the Jacobian's null space is not
/// identifiable on its own: it gets no `z` (as in `calib/tests/extensions.rs`).
pub const NULL_SHARE_MAX: f64 = 0.1;

/// The calibration's inputs for scoring: the robot, the calibration and its extensions' regressors
/// for every row of the run's table.
pub struct Scored<'a> {
    /// The nominal robot.
    pub model: &'a sim::Model,
    /// The calibration.
    pub cal: &'a Calibration,
    /// Regressors of every table row (none for the kinematic model).
    pub regs: Regressors,
}

impl<'a> Scored<'a> {
    /// The regressors of every row of `table` under the calibration's extension settings, at its
    /// estimate (as `robocal predict` builds them).
    pub fn new(
        model: &'a sim::Model,
        cal: &'a Calibration,
        table: &MeasurementTable,
    ) -> calib::Result<Self> {
        let regs = match &cal.extensions {
            Some(s) => {
                let rows: Vec<usize> = (0..table.len()).collect();
                Regressors::build(model, s, table, &rows, "sweep run", Some(&cal.params))?
            }
            None => Regressors::none(),
        };
        Ok(Scored { model, cal, regs })
    }

    /// The physical model's parameters (before a learned stage changed them).
    fn physical(&self) -> &KinematicParams {
        self.cal.physical.as_ref().unwrap_or(&self.cal.params)
    }

    fn coef(&self, r: usize) -> &[f64] {
        if self.regs.is_empty() {
            &[]
        } else {
            self.regs.row(r)
        }
    }
}

/// `L` (np × r, physical units) with `C = L Lᵀ` the calibration's covariance:
/// `L = σ̂ D V_r Σ_r⁻¹`, `σ̂²` the variance factor (`χ²/dof`, or 1 without degrees of freedom).
pub fn covariance_factor(cal: &Calibration) -> DMatrix<f64> {
    let sub = &cal.subspace;
    let (np, r) = (sub.n_params(), sub.rank);
    let vf = if cal.report.dof > 0 {
        cal.report.chi2_per_dof
    } else {
        1.0
    };
    let sf = vf.sqrt();
    let mut l = DMatrix::zeros(np, r);
    for c in 0..r {
        let s = sub.singular_values[c];
        for k in 0..np {
            l[(k, c)] = sf * sub.scales[k] * sub.v[(k, c)] / s;
        }
    }
    l
}

/// Held-out scores (m; NaN without held-out rows).
pub struct HeldOut {
    /// RMS of |predicted − true| (m).
    pub rms_m: f64,
    /// Largest |predicted − true| (m).
    pub max_m: f64,
    /// What the covariance predicts for `rms_m` (m).
    pub predicted_m: f64,
    /// RMS error of the nominal robot with base and target fitted (m).
    pub nominal_rms_m: f64,
}

/// Errors of the calibrated model (extensions and learned correction included) and of the nominal
/// (base and target only) model against the noise-free truth `p_true` (tracker frame, m, per table
/// row) on `rows`, and the covariance's prediction `√(mean trace(J C Jᵀ))`, with
/// `trace(J C Jᵀ) = ‖J L‖²_F` accumulated without allocating per row.
pub fn held_out(
    sc: &Scored<'_>,
    l: &DMatrix<f64>,
    table: &MeasurementTable,
    rows: &[usize],
    p_true: &[Vector3<f64>],
) -> HeldOut {
    if rows.is_empty() {
        return HeldOut {
            rms_m: f64::NAN,
            max_m: f64::NAN,
            predicted_m: f64::NAN,
            nominal_rms_m: f64::NAN,
        };
    }
    let (model, cal) = (sc.model, sc.cal);
    let layout = &cal.layout;
    let np = layout.len();
    let calibrated = Prediction::new(model, &cal.params).with_learned(cal.learned.as_ref());
    let physical = Prediction::new(model, sc.physical());
    let nominal = Prediction::new(model, &cal.before);
    let none = Regressors::none();
    let mut scratch = calibrated.scratch();
    let mut jbuf = vec![0.0; 3 * np];
    let (mut e2, mut emax, mut pred2, mut nom2) = (0.0, 0.0f64, 0.0, 0.0);
    for &row in rows {
        let q = table.q_row(row);
        nom2 += (nominal.row(&none, row, q, &mut scratch) - p_true[row]).norm_squared();
        // The physical model's Jacobian at this row first: the learned row below reuses the scratch.
        let pred = physical.physical(&sc.regs, row, q, &mut scratch);
        position_jacobian_row(
            physical.chain(),
            layout,
            &scratch,
            &pred,
            0,
            sc.coef(row),
            &mut jbuf,
        );
        let p = match cal.learned {
            Some(_) => calibrated.row(&sc.regs, row, q, &mut scratch),
            None => pred.p_tracker,
        };
        let e = (p - p_true[row]).norm();
        e2 += e * e;
        emax = emax.max(e);
        for a in 0..3 {
            let ja = &jbuf[a * np..(a + 1) * np];
            for c in 0..l.ncols() {
                let v: f64 = ja.iter().zip(l.column(c).iter()).map(|(x, y)| x * y).sum();
                pred2 += v * v;
            }
        }
    }
    let n = rows.len() as f64;
    HeldOut {
        rms_m: (e2 / n).sqrt(),
        max_m: emax,
        predicted_m: (pred2 / n).sqrt(),
        nominal_rms_m: (nom2 / n).sqrt(),
    }
}

/// Errors of the identifiable combinations in units of their predicted σ.
pub struct Combinations {
    /// Combinations scored.
    pub count: usize,
    /// Mean of z² (NaN without any).
    pub z2_mean: f64,
    /// Largest |z|.
    pub z_abs_max: f64,
    /// Combinations with |z| > 3.
    pub beyond_3sigma: usize,
}

/// The identifiable combinations at the training poses (one position per distinct pose, as in
/// `calib/tests/recovery.rs`): `B = J L = U S Wᵀ`; the combinations are U's columns, their predicted
/// σ the singular values `S` (m), their errors `z = S⁻¹ Uᵀ (p_estimated − p_true)` with the physical
/// model's prediction.
pub fn combinations(
    sc: &Scored<'_>,
    l: &DMatrix<f64>,
    table: &MeasurementTable,
    rows: &[usize],
    p_true: &[Vector3<f64>],
) -> Combinations {
    let layout = &sc.cal.layout;
    let np = layout.len();
    let mut first_rows: Vec<usize> = Vec::with_capacity(rows.len());
    let mut last_pose = None;
    for &row in rows {
        if last_pose != Some(table.pose[row]) {
            first_rows.push(row);
            last_pose = Some(table.pose[row]);
        }
    }
    let physical = Prediction::new(sc.model, sc.physical());
    let mut scratch = physical.scratch();
    let mut jbuf = vec![0.0; 3 * np];
    let m = 3 * first_rows.len();
    let mut j = DMatrix::zeros(m, np);
    let mut d = DVector::zeros(m);
    for (i, &row) in first_rows.iter().enumerate() {
        let pred = physical.physical(&sc.regs, row, table.q_row(row), &mut scratch);
        position_jacobian_row(
            physical.chain(),
            layout,
            &scratch,
            &pred,
            0,
            sc.coef(row),
            &mut jbuf,
        );
        for a in 0..3 {
            for k in 0..np {
                j[(3 * i + a, k)] = jbuf[a * np + k];
            }
            d[3 * i + a] = pred.p_tracker[a] - p_true[row][a];
        }
    }
    let mut out = Combinations {
        count: 0,
        z2_mean: f64::NAN,
        z_abs_max: 0.0,
        beyond_3sigma: 0,
    };
    if l.ncols() == 0 || m == 0 {
        return out;
    }
    let svd = (&j * l).svd(true, false);
    let Some(u) = &svd.u else {
        return out;
    };
    let smax = svd.singular_values.max();
    let mut z2 = 0.0;
    for (c, &s) in svd.singular_values.iter().enumerate() {
        if s <= 1e-8 * smax || s == 0.0 {
            continue;
        }
        let z = u.column(c).dot(&d) / s;
        out.count += 1;
        z2 += z * z;
        out.z_abs_max = out.z_abs_max.max(z.abs());
        if z.abs() > 3.0 {
            out.beyond_3sigma += 1;
        }
    }
    if out.count > 0 {
        out.z2_mean = z2 / out.count as f64;
    }
    out
}

/// Per cause: parameters in the fitted model and the mean z² of those scored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CauseScore {
    /// Parameters of the cause in the fitted model (0: the cause is not in it).
    pub params: usize,
    /// Mean of z² over its parameters with a `z` (NaN without any).
    pub z2_mean: f64,
}

/// Each extension parameter of the calibration against the truth `effects` injected into the run
/// (`run` its index): estimate, truth ([`truth_of`]), σ (the covariance's diagonal) and
/// `z = (estimate − truth)/σ`, left NaN for a parameter not identifiable on its own
/// ([`NULL_SHARE_MAX`]) or without a mapped truth. Returns the rows (model file order) and the score
/// of each cause of [`Cause::ALL`], in that order.
pub fn extension_params(
    model: &sim::Model,
    cal: &Calibration,
    effects: &sim::effects::Effects,
    run: usize,
) -> (Vec<ParamRow>, Vec<CauseScore>) {
    let mut rows = Vec::new();
    let mut sums = vec![(0usize, 0usize, 0.0f64); Cause::ALL.len()];
    let (Some(settings), sub) = (&cal.extensions, &cal.subspace) else {
        return (rows, causes_of(&sums));
    };
    let physical = cal.physical.as_ref().unwrap_or(&cal.params);
    for (e, p) in cal.layout.extensions.iter().enumerate() {
        let kk = cal.layout.extension(e);
        let null_share = sub
            .v
            .row(kk)
            .columns(sub.rank, sub.n_params() - sub.rank)
            .norm();
        let identifiable = null_share <= NULL_SHARE_MAX;
        let sigma = cal.covariance[(kk, kk)].max(0.0).sqrt();
        let estimate = physical.extension[e];
        let truth = truth_of(model, effects, settings, p).unwrap_or(f64::NAN);
        let z = if identifiable && sigma > 0.0 {
            (estimate - truth) / sigma
        } else {
            f64::NAN
        };
        if let Some(c) = Cause::ALL.iter().position(|c| *c == p.cause) {
            sums[c].0 += 1;
            if z.is_finite() {
                sums[c].1 += 1;
                sums[c].2 += z * z;
            }
        }
        rows.push(ParamRow {
            run: run as i64,
            cause: p.cause.name().to_string(),
            param: p.name(),
            unit: p.unit.symbol().to_string(),
            estimate,
            truth,
            sigma,
            z,
            identifiable,
        });
    }
    (rows, causes_of(&sums))
}

fn causes_of(sums: &[(usize, usize, f64)]) -> Vec<CauseScore> {
    sums.iter()
        .map(|&(params, scored, z2)| CauseScore {
            params,
            z2_mean: if scored > 0 {
                z2 / scored as f64
            } else {
                f64::NAN
            },
        })
        .collect()
}
