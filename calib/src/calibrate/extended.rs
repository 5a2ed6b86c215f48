//! Extended models: refits at the estimated equilibrium, the payload centre of mass, and the search
//! over a cause's alternative settings.

use super::{Calibration, CalibrationOptions, Dataset, WarmStart, calibrate_with, observations};
use crate::error::{CalibError, Result};
use crate::extensions::ExtensionSettings;
use crate::lm::LeastSquaresProblem;
use crate::problem::KinematicProblem;
use nalgebra::{DMatrix, DVector, Vector3};
use sim::Model;

/// Most outer iterations that move the torque evaluation to the estimated equilibrium (see
/// [`Regressors::build`]) and, with payload, re-estimate its centre of mass.
pub const EQUILIBRIUM_REFITS: usize = 12;

/// One Gauss–Newton step (m) for the payload's centre of mass in the flange frame, taken jointly with
/// every other parameter at `cal`: the weighted least-squares step of the stacked Jacobian
/// `[J D, J_c s_c]` (the analytic Jacobian of the identifiable parameters, scaled, and central
/// differences of the residuals in each coordinate of the centre of mass, scaled by 1 cm), minimum-norm
/// in the unidentifiable directions; only its centre-of-mass part is returned (the refit does the rest).
fn payload_com_step(
    model: &Model,
    train: &Dataset<'_>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    cal: &Calibration,
) -> Result<Vector3<f64>> {
    const H: f64 = 1e-3;
    const COM_SCALE_M: f64 = 1e-2;
    let at = &cal.params.extension;
    let residuals = |s: &ExtensionSettings| -> Result<Vec<f64>> {
        let obs = observations(model, train, options, Some(s), at)?;
        let all: Vec<usize> = (0..cal.layout.len()).collect();
        let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all);
        let mut r = vec![0.0; prob.n_residuals()];
        prob.set_params(&vec![0.0; cal.layout.len()]);
        prob.residuals(&mut r);
        Ok(r)
    };
    let obs = observations(model, train, options, Some(settings), at)?;
    let p = cal.layout.len();
    let all: Vec<usize> = (0..p).collect();
    let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all);
    let m = prob.n_residuals();
    let mut r0 = vec![0.0; m];
    prob.set_params(&vec![0.0; p]);
    prob.residuals(&mut r0);
    // [J D, J_c s_c, r]: the scaled Jacobian, the centre of mass's columns, the residuals.
    let n = p + 3;
    let mut j = {
        let mut jk = DMatrix::zeros(m, p);
        prob.jacobian(&mut jk);
        jk.resize_horizontally(n + 1, 0.0)
    };
    let scales = options.scales.vector(&cal.layout);
    for c in 0..p {
        let s = if cal.subspace.scales.get(c).is_some_and(|v| *v == 0.0) {
            0.0
        } else {
            scales[c]
        };
        j.column_mut(c).scale_mut(s);
    }
    for axis in 0..3 {
        let mut plus = settings.clone();
        plus.payload_com_m[axis] += H;
        let mut minus = settings.clone();
        minus.payload_com_m[axis] -= H;
        let (rp, rm) = (residuals(&plus)?, residuals(&minus)?);
        for row in 0..m {
            j[(row, p + axis)] = (rp[row] - rm[row]) / (2.0 * H) * COM_SCALE_M;
        }
    }
    // The least-squares step from the R factor of [J r] (tall-skinny QR: the top of its last column
    // is Qᵀr), then the SVD of the small R: the same minimum-norm solution as the SVD of J, without
    // the m × (p + 3) left singular vectors.
    j.column_mut(n).copy_from_slice(&r0);
    let r_aug = crate::linalg::r_factor(&j);
    drop(j);
    let rows = n.min(r_aug.nrows());
    let mut r = DMatrix::zeros(n, n);
    r.view_mut((0, 0), (rows, n))
        .copy_from(&r_aug.view((0, 0), (rows, n)));
    let mut qtr = DVector::zeros(n);
    qtr.rows_mut(0, rows)
        .copy_from(&r_aug.view((0, n), (rows, 1)));
    let svd = r.svd(true, true);
    let smax = svd.singular_values.max();
    let step = svd
        .solve(&qtr, 1e-8 * smax)
        .map_err(|e| CalibError::BadValue {
            context: train.name.clone(),
            field: "payload".into(),
            value: String::new(),
            problem: format!("payload centre of mass: {e}"),
        })?;
    Ok(Vector3::new(
        -step[p] * COM_SCALE_M,
        -step[p + 1] * COM_SCALE_M,
        -step[p + 2] * COM_SCALE_M,
    ))
}

/// [`calibrate_with`] for an extended model. With a cause whose regressors depend on the link angles
/// ([`ExtensionSettings::needs_equilibrium`], joint compliance) it is refitted with the torques at
/// the estimated equilibrium until the compliances settle (relative change below 10⁻⁶ of their scale);
/// when the table carries a payload, each refit also moves the payload's centre of mass (unknown to the
/// table, [`ExtensionSettings::payload_com_m`]) by a Gauss–Newton step, until it moves less than 1 µm.
/// The covariance treats the centre of mass as known.
pub(super) fn calibrate_extended(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    warm: Option<WarmStart<'_>>,
) -> Result<Calibration> {
    let mut settings = settings.clone();
    let mut cal = calibrate_with(
        model,
        train,
        test,
        options,
        Some(&settings),
        &[],
        warm,
        None,
    )?;
    if !settings.needs_equilibrium() {
        return Ok(cal);
    }
    let payload = train
        .table
        .payload
        .as_ref()
        .is_some_and(|m| train.rows.iter().any(|&r| m[r] > 0.0));
    let mut health = cal.report.health;
    for _ in 0..EQUILIBRIUM_REFITS {
        let at = cal.params.extension.clone();
        let com_step = if payload {
            let d = payload_com_step(model, train, options, &settings, &cal)?;
            for (c, d) in settings.payload_com_m.iter_mut().zip(d.iter()) {
                *c += d;
            }
            d.norm()
        } else {
            0.0
        };
        // A fit that started at the same model's solution elsewhere (a fold, the refit of a
        // screened model on every pose) refits from its last refit, in the basin it started in; a
        // fit from the closed form refits from the closed form (a refit started at the one before
        // can settle in another local minimum, see `diagnose::Start`).
        let refit_start = warm.map(|w| WarmStart {
            before: &cal.before,
            physical: &cal.params,
            extensions: &cal.layout.extensions,
            lean: w.lean,
            payload_com_m: Some(settings.payload_com_m),
            shared: None,
        });
        let next = calibrate_with(
            model,
            train,
            test,
            options,
            Some(&settings),
            &at,
            refit_start,
            // The base-and-target fit (nominal joints, extensions at zero) is the first fit's.
            Some((&cal.before, &cal.report.before)),
        )?;
        let change = next
            .params
            .extension
            .iter()
            .zip(&at)
            .zip(&next.layout.extensions)
            .map(|((a, b), p)| (a - b).abs() / p.scale)
            .fold(0.0, f64::max);
        health.merge(&next.report.health);
        cal = next;
        if change < 1e-6 && com_step < 1e-6 {
            break;
        }
    }
    cal.report.health = health;
    Ok(cal)
}

/// [`calibrate_extended`] for `settings` and every alternative its causes offer
/// ([`ExtensionSettings::alternatives`]); keeps the calibration with the smallest training `χ²` (the
/// first of equal ones).
pub(super) fn calibrate_best(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    warm: Option<WarmStart<'_>>,
) -> Result<Calibration> {
    let alternatives = settings.alternatives(train.table, &train.rows);
    if alternatives.is_empty() {
        return calibrate_extended(model, train, test, options, settings, warm);
    }
    let mut best: Option<Calibration> = None;
    for s in &alternatives {
        let cal = calibrate_extended(model, train, test, options, s, warm)?;
        if best
            .as_ref()
            .is_none_or(|b| cal.report.after.solver.cost_final < b.report.after.solver.cost_final)
        {
            best = Some(cal);
        }
    }
    Ok(best.expect("at least one alternative"))
}
