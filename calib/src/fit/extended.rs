//! Extended models: refits at the estimated equilibrium, the payload centre of mass, and the search
//! over a cause's alternative settings.

use super::{
    Calibration, CalibrationOptions, Dataset, Stage, WarmStart, kinematic_fit, observations,
};
use crate::error::{CalibError, Result};
use crate::fit::problem::{KinematicProblem, Observations};
use crate::lm::LeastSquaresProblem;
use crate::model::extensions::ExtensionSettings;
use nalgebra::{DMatrix, DVector, Vector3};
use sim::Model;

/// Most outer iterations that move the torque evaluation to the estimated equilibrium (see
/// [`Regressors::build`]) and, with payload, re-estimate its centre of mass.
pub const EQUILIBRIUM_REFITS: usize = 12;

/// The equilibrium refits stop when a refit moves the fit by less than this many of its standard
/// deviations ([`crate::lm::Subspace::step_in_sigmas`]): the fixed point is then known far better
/// than the data know the parameters. (Refits from the closed form differ by the solver's own
/// tolerance, along weakly determined combinations: their relative change alone can stall above
/// 10⁻⁶ for all [`EQUILIBRIUM_REFITS`].)
pub const EQUILIBRIUM_SIGMAS: f64 = 1e-3;

/// How far (standard deviations of the fit) the fixed point of the equilibrium refits still lies
/// from a refit that moved `moved`, after one that moved `before`: with linear convergence at the
/// rate `ρ = moved / before`, the moves still to come sum to `moved ρ / (1 − ρ)`; without a rate, or
/// one above ½ (no clear contraction), at most `moved` (the sum for `ρ = ½`).
fn distance_left(moved: f64, before: Option<f64>) -> f64 {
    match before {
        Some(b) if b > 0.0 && moved < 0.5 * b => {
            let rate = moved / b;
            moved * rate / (1.0 - rate)
        }
        _ => moved,
    }
}

/// One Gauss–Newton step (m) for the payload's centre of mass in the flange frame, taken jointly with
/// every other parameter at `cal`: the weighted least-squares step of the stacked Jacobian
/// `[J D, J_c s_c]` (the analytic Jacobian, scaled, and forward differences of 1 mm of the residuals
/// in each coordinate of the centre of mass, scaled by 1 cm), with the rows `cal` excluded as gross
/// errors left out; only its centre-of-mass part is returned (the refit does the rest). (One-sided
/// differences suffice: the payload's gravity torque is linear in its centre of mass, so the residuals
/// are too, up to the equilibrium's second-order coupling; central differences gave the same
/// diagnosis of the bench's 100,000 poses to six digits, at twice the cost.)
///
/// The other parameters are eliminated through the SVD `J D = U S Vᵀ` of the rank decision
/// (identifiable directions only): with `Y = S⁻¹ Vᵀ (J D)ᵀ J_c s_c = Uᵀ J_c s_c` and
/// `y = S⁻¹ Vᵀ (J D)ᵀ r = Uᵀ r`, the step is `−K⁺ h` with the Schur complement
/// `K = (J_c s_c)ᵀ J_c s_c − Yᵀ Y` (the part of the centre of mass's columns that the other parameters
/// cannot take up) and `h = (J_c s_c)ᵀ r − Yᵀ y`; directions of `K` below 10⁻¹² of the largest
/// diagonal entry of `(J_c s_c)ᵀ J_c s_c` (a singular value 10⁻⁶ of the columns' own) are not moved.
/// The SVD is the fit's own rank decision (at these parameters and weights), except after a robust
/// fit, whose final weights these rows do not carry: the other parameters move along the directions
/// the refit moves, and the weakly determined combinations it holds (below
/// [`crate::lm::LmOptions::min_singular_value`]) take up no part of the centre of mass's signal.
fn payload_com_step(
    model: &Model,
    train: &Dataset<'_>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    cal: &Calibration,
) -> Result<ComStep> {
    const H: f64 = 1e-3;
    const COM_SCALE_M: f64 = 1e-2;
    const K_RTOL: f64 = 1e-12;
    let at = Some(&cal.params);
    let p = cal.layout.len();
    let all: Vec<usize> = (0..p).collect();
    let prepared = |s: &ExtensionSettings| -> Result<Observations> {
        let mut obs = observations(model, train, options, Some(s), at)?;
        super::outliers::exclude(&mut obs, &cal.report.excluded);
        Ok(obs)
    };
    let residuals = |s: &ExtensionSettings| -> Result<Vec<f64>> {
        let obs = prepared(s)?;
        let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all.clone());
        let mut r = vec![0.0; prob.n_residuals()];
        prob.set_params(&vec![0.0; p]);
        prob.residuals(&mut r);
        Ok(r)
    };
    let obs = prepared(settings)?;
    let mut prob = KinematicProblem::new(model, &obs, cal.params.clone(), all.clone());
    let m = prob.n_residuals();
    let mut r0 = vec![0.0; m];
    prob.set_params(&vec![0.0; p]);
    prob.residuals(&mut r0);
    // The centre of mass's scaled columns J_c s_c (forward differences from r0).
    let mut jc = [vec![0.0; m], vec![0.0; m], vec![0.0; m]];
    for (axis, col) in jc.iter_mut().enumerate() {
        let mut plus = settings.clone();
        plus.payload_com_m[axis] += H;
        for ((c, a), b) in col.iter_mut().zip(&residuals(&plus)?).zip(&r0) {
            *c = (a - b) / H * COM_SCALE_M;
        }
    }
    // The rank decision's SVD of `J D`: the fit's own, when its rows carried the weights these do
    // (no robust loss; the gross errors are left out above).
    let own;
    let sub = if options.robust.is_none() && cal.subspace.n_params() == p {
        &cal.subspace
    } else {
        let mut jac = DMatrix::zeros(m, p);
        prob.jacobian(&mut jac);
        own = crate::lm::Subspace::analyze(
            &jac,
            options.scales.vector(&cal.layout).as_slice(),
            options.lm.rank_rtol,
            options.lm.min_singular_value,
        );
        &own
    };
    // (J D)ᵀ [r, J_c s_c] in one pass over the rows, then Uᵀ w = S⁻¹ Vᵀ (J D)ᵀ w.
    let jtw =
        prob.scaled_jacobian_transpose_times_columns(&sub.scales, &[&r0, &jc[0], &jc[1], &jc[2]]);
    let u_t = |c: usize| -> DVector<f64> {
        DVector::from_fn(sub.rank, |k, _| {
            (0..p).map(|i| sub.v[(i, k)] * jtw[(i, c)]).sum::<f64>() / sub.singular_values[k]
        })
    };
    let y = u_t(0);
    let ys: Vec<DVector<f64>> = (1..4).map(u_t).collect();
    let dot = crate::linalg::dot;
    let mut k = nalgebra::Matrix3::zeros();
    let mut h = Vector3::zeros();
    for a in 0..3 {
        h[a] = dot(&jc[a], &r0) - ys[a].dot(&y);
        for b in 0..3 {
            k[(a, b)] = dot(&jc[a], &jc[b]) - ys[a].dot(&ys[b]);
        }
    }
    let own = (0..3).map(|a| dot(&jc[a], &jc[a])).fold(0.0, f64::max);
    let eig = k.symmetric_eigen();
    let mut step = Vector3::zeros();
    // G = D Vᵣ Sᵣ⁻¹ Y: how the other parameters follow a move of the centre of mass that their own
    // columns take up (p × 3, physical units per scaled centre-of-mass unit).
    let g = DMatrix::from_fn(p, 3, |i, a| {
        sub.scales[i]
            * (0..sub.rank)
                .map(|k| sub.v[(i, k)] * ys[a][k] / sub.singular_values[k])
                .sum::<f64>()
    });
    let mut inflation = DMatrix::zeros(p, p);
    for c in 0..3 {
        let lambda = eig.eigenvalues[c];
        if lambda > K_RTOL * own && lambda.is_finite() {
            let v = eig.eigenvectors.column(c);
            step -= v * (v.dot(&h) / lambda);
            let gv = &g * DVector::from_column_slice(v.as_slice());
            inflation += &gv * gv.transpose() / lambda;
        }
    }
    if !step.iter().all(|v| v.is_finite()) {
        return Err(CalibError::BadValue {
            context: train.name.clone(),
            field: "payload".into(),
            value: String::new(),
            problem: "payload centre of mass: the Gauss–Newton step is not finite".into(),
        });
    }
    Ok(ComStep {
        step_m: step * COM_SCALE_M,
        covariance_inflation: inflation,
    })
}

/// A Gauss–Newton step of the payload's centre of mass ([`payload_com_step`]) and what its
/// uncertainty adds to the other parameters' covariance.
struct ComStep {
    /// The step (m, flange frame).
    step_m: Vector3<f64>,
    /// `G K⁺ Gᵀ` (p × p, physical units, to be multiplied by the variance factor): with the
    /// centre of mass estimated jointly, the normal matrix of the identifiable coordinates
    /// `u = S Vᵀ D⁻¹ θ` and the centre of mass `c` is `[[I, Y], [Yᵀ, C]]`, and the marginal
    /// covariance of `u` is `(I − Y C⁻¹ Yᵀ)⁻¹ = I + Y K⁻¹ Yᵀ` (Woodbury, `K = C − Yᵀ Y`): the
    /// covariance of a known centre of mass plus this term, `G = D Vᵣ Sᵣ⁻¹ Y`. Directions of `K`
    /// not moved by the step add nothing.
    covariance_inflation: DMatrix<f64>,
}

/// [`kinematic_fit`] for an extended model. With a cause whose regressors depend on the link angles
/// ([`ExtensionSettings::needs_equilibrium`], joint compliance) it is refitted with the torques at
/// the estimated equilibrium until the fit settles: the refits still to come would move it by less
/// than [`EQUILIBRIUM_SIGMAS`] of its standard deviations ([`distance_left`], from the last two
/// refits' moves), or the extension values change by less than 10⁻⁶ of their scale. When the table
/// carries a payload, each refit also moves the payload's centre of mass (unknown to the table,
/// [`ExtensionSettings::payload_com_m`]) by a Gauss–Newton step, until the steps still to come sum
/// to less than 1 µm. A warm start ([`WarmStart`]) evaluates the first fit's torques at the
/// equilibrium it starts from. The covariance includes the centre of mass's uncertainty
/// ([`ComStep::covariance_inflation`], at the last step).
pub(super) fn fit_at_equilibrium(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    warm: Option<WarmStart<'_>>,
) -> Result<Calibration> {
    let mut settings = settings.clone();
    // A warm fit evaluates its first torques at the equilibrium of the calibration it starts from
    // (near its own): its first refit then only confirms it. A cold fit, at the commanded angles.
    let first_at = match warm {
        Some(w)
            if settings.needs_equilibrium() && w.physical.extension.len() == w.extensions.len() =>
        {
            let mut at = w.physical.clone();
            at.extension = w.extension_for(&settings.params(model));
            Some(at)
        }
        _ => None,
    };
    let mut cal = kinematic_fit(
        model,
        train,
        &Stage {
            test,
            options,
            extensions: Some(&settings),
            at: first_at.as_ref(),
            warm,
            same_before: None,
        },
    )?;
    if !settings.needs_equilibrium() {
        return Ok(cal);
    }
    // The centre of mass is searched only where the regressors read it through the robot's statics
    // (without masses, joint compliance has its own linear products with it).
    let payload = (settings.needs_gravity_torque() || settings.needs_gravity_moment())
        && train
            .table
            .payload
            .as_ref()
            .is_some_and(|m| train.rows.iter().any(|&r| m[r] > 0.0));
    let mut health = cal.report.health;
    let (mut last_move, mut last_com): (Option<f64>, Option<f64>) = (None, None);
    let mut inflation: Option<DMatrix<f64>> = None;
    for _ in 0..EQUILIBRIUM_REFITS {
        let at = cal.params.clone();
        let com_step = if payload {
            let d = payload_com_step(model, train, options, &settings, &cal)?;
            for (c, d) in settings.payload_com_m.iter_mut().zip(d.step_m.iter()) {
                *c += d;
            }
            inflation = Some(d.covariance_inflation);
            d.step_m.norm()
        } else {
            0.0
        };
        // A fit that started at the same model's solution elsewhere (a fold, the refit of a
        // screened model on every pose) refits from its last refit, in the basin it started in; a
        // fit from the closed form refits from the closed form (a refit started at the one before
        // can settle in another local minimum while the equilibrium still moves, see
        // `diagnose::Start`) until a refit moved it by less than one standard deviation: the
        // minimum then lies within that of the last refit's.
        let near = last_move.is_some_and(|m| m < 1.0);
        let refit_start = (warm.is_some() || near).then(|| WarmStart {
            before: &cal.before,
            physical: &cal.params,
            extensions: &cal.layout.extensions,
            lean: warm.is_some_and(|w| w.lean),
            payload_com_m: Some(settings.payload_com_m),
            shared: None,
        });
        let next = kinematic_fit(
            model,
            train,
            &Stage {
                test,
                options,
                extensions: Some(&settings),
                at: Some(&at),
                warm: refit_start,
                // The base-and-target fit (nominal joints, extensions at zero) is the first fit's.
                same_before: Some((&cal.before, &cal.report.before)),
            },
        )?;
        let change = next
            .params
            .extension
            .iter()
            .zip(&at.extension)
            .zip(&next.layout.extensions)
            .map(|((a, b), p)| (a - b).abs() / p.scale)
            .fold(0.0, f64::max);
        // The refit's move in standard deviations of the fit (every parameter).
        // (An exact fit, χ² = 0, measures it in units of the noise model.)
        let vf = next.report.variance_factor();
        let moved_sigmas = next.subspace.step_in_sigmas(
            &cal.params.difference(&next.layout, &next.params),
            if vf > 0.0 { vf } else { 1.0 },
        );
        health.merge(&next.report.health);
        cal = next;
        let left = distance_left(moved_sigmas, last_move);
        let com_left = distance_left(com_step, last_com);
        (last_move, last_com) = (Some(moved_sigmas), Some(com_step));
        if (change < 1e-6 || left < EQUILIBRIUM_SIGMAS) && com_left < 1e-6 {
            break;
        }
    }
    cal.report.health = health;
    if let Some(inflation) = inflation.filter(|i| i.shape() == cal.covariance.shape()) {
        // The centre of mass is estimated, not known: its uncertainty goes into the covariance
        // (linearised at the last step's point, within EQUILIBRIUM_SIGMAS of the final fit's).
        let vf = cal.report.variance_factor();
        cal.covariance += inflation * if vf > 0.0 { vf } else { 1.0 };
        cal.report.parameters =
            super::estimates::estimates(&cal.layout, &cal.params, &cal.covariance, &cal.subspace);
        cal.report.strong_correlations = super::estimates::correlations(
            &cal.layout,
            &cal.covariance,
            &cal.report.unidentifiable,
        );
    }
    Ok(cal)
}

/// [`fit_at_equilibrium`] for `settings` and every alternative its causes offer
/// ([`ExtensionSettings::alternatives`]); keeps the calibration with the smallest training `χ²` (the
/// first of equal ones).
pub(super) fn best_extended_fit(
    model: &Model,
    train: &Dataset<'_>,
    test: Option<&Dataset<'_>>,
    options: &CalibrationOptions,
    settings: &ExtensionSettings,
    warm: Option<WarmStart<'_>>,
) -> Result<Calibration> {
    let alternatives = settings.alternatives(train.table, &train.rows);
    if alternatives.is_empty() {
        return fit_at_equilibrium(model, train, test, options, settings, warm);
    }
    let mut best: Option<Calibration> = None;
    for s in &alternatives {
        let cal = fit_at_equilibrium(model, train, test, options, s, warm)?;
        if best
            .as_ref()
            .is_none_or(|b| cal.report.after.solver.cost_final < b.report.after.solver.cost_final)
        {
            best = Some(cal);
        }
    }
    Ok(best.expect("at least one alternative"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::spec::ModelSpec;
    use sim::scenario::{Overrides, Scenario};

    #[test]
    fn distance_left_sums_the_geometric_tail_of_the_moves() {
        // No rate yet, or no clear contraction: the move itself (the tail's sum at ρ = ½).
        assert_eq!(distance_left(0.5, None), 0.5);
        assert_eq!(distance_left(0.8, Some(1.0)), 0.8);
        assert_eq!(distance_left(0.0, Some(0.0)), 0.0);
        // ρ = 0.1 after a move of 0.1: 0.01 + 0.001 + … = 0.1 · 0.1 / 0.9.
        assert!((distance_left(0.1, Some(1.0)) - 0.01 / 0.9).abs() < 1e-16);
    }

    /// The centre-of-mass step against the dense joint least squares of the same residuals: the SVD
    /// of `[J D Vᵣ, J_c s_c]` (the other parameters along the fit's identifiable directions `Vᵣ`, as
    /// the refit moves them; the centre of mass's columns by central differences of 0.1 mm), solved
    /// for the step that minimises `‖[J D Vᵣ, J_c s_c] x + r‖`, at a calibration whose centre of mass
    /// is moved 4 mm off its estimate.
    #[test]
    fn payload_com_step_matches_the_dense_joint_least_squares() {
        let model = sim::robots::load_builtin("iiwa7").unwrap();
        let text = format!(
            "{}\n[effects.compliance]\nstiffness_nm_per_rad = [inf, 1.2e4, inf, 8e3, inf, 1.5e4, inf]\n\
             [campaign.payload]\nchoice_kg = [0.0, 3.0, 6.0]\ncom_m = [0.0, 0.01, 0.06]\n",
            include_str!("../../../scenarios/iiwa7_kinematic.toml")
        );
        let sc = Scenario::parse(&text, "com test", std::path::Path::new(".")).unwrap();
        let res = sc
            .resolve(&Overrides {
                seed: Some(3),
                poses: Some(120),
                noise: None,
            })
            .unwrap();
        let dir = std::env::temp_dir().join(format!("robocal_com_step_{}", std::process::id()));
        sim::generate::generate(&res, &dir, None).unwrap();
        let table = sim::measurement_table::read(&dir.join("measurements.parquet")).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        let train = Dataset::all(&table, "com test");
        let options = CalibrationOptions::default();
        let spec = ModelSpec::parse("kinematic+joint_compliance").unwrap();
        let cal = super::super::fit(
            &model,
            &train,
            &super::super::FitRequest::new(&spec, &options),
        )
        .unwrap();
        let mut settings = cal.extensions.clone().unwrap();
        let off = Vector3::new(0.004, -0.003, 0.002);
        for (c, d) in settings.payload_com_m.iter_mut().zip(off.iter()) {
            *c += d;
        }
        let com = payload_com_step(&model, &train, &options, &settings, &cal).unwrap();
        let step = com.step_m;

        // The dense reference.
        let p = cal.layout.len();
        let all: Vec<usize> = (0..p).collect();
        let residuals = |s: &ExtensionSettings| {
            let obs = observations(&model, &train, &options, Some(s), Some(&cal.params)).unwrap();
            let mut prob = KinematicProblem::new(&model, &obs, cal.params.clone(), all.clone());
            let mut r = vec![0.0; prob.n_residuals()];
            prob.residuals(&mut r);
            (r, obs)
        };
        let (r0, obs) = residuals(&settings);
        let m = r0.len();
        let mut prob = KinematicProblem::new(&model, &obs, cal.params.clone(), all.clone());
        let mut j = DMatrix::zeros(m, p);
        prob.jacobian(&mut j);
        for c in 0..p {
            j.column_mut(c).scale_mut(cal.subspace.scales[c]);
        }
        let r = cal.subspace.rank;
        let jv = &j * cal.subspace.v.columns(0, r);
        let mut a = DMatrix::zeros(m, r + 3);
        a.columns_mut(0, r).copy_from(&jv);
        let h = 1e-4;
        for axis in 0..3 {
            let (mut plus, mut minus) = (settings.clone(), settings.clone());
            plus.payload_com_m[axis] += h;
            minus.payload_com_m[axis] -= h;
            let (rp, rm) = (residuals(&plus).0, residuals(&minus).0);
            for row in 0..m {
                a[(row, r + axis)] = (rp[row] - rm[row]) / (2.0 * h) * 1e-2;
            }
        }
        let svd = a.clone().svd(true, true);
        let tol = 1e-8 * svd.singular_values.max();
        let x = svd.solve(&(-DVector::from_column_slice(&r0)), tol).unwrap();
        let reference = Vector3::new(x[r], x[r + 1], x[r + 2]) * 1e-2;
        // Apart by the forward differences' truncation: 8·10⁻⁵ of the step here.
        assert!(
            (step - reference).norm() < 1e-3 * reference.norm(),
            "step {step:?} m, dense reference {reference:?} m"
        );
        // Moved back near the estimate: the step undoes most of the 4 mm offset.
        assert!((step + off).norm() < 0.25 * off.norm(), "step {step:?} m");

        // The covariance's inflation against the dense joint normal matrix, at the estimate (where
        // the fit's SVD is that of its Jacobian): the marginal covariance of the identifiable
        // coordinates with the centre of mass estimated, `[(AᵀA)⁻¹]ᵣᵣ`, less the one with it
        // known, `(Vᵣᵀ (JD)ᵀ JD Vᵣ)⁻¹`, back in physical units by `D Vᵣ`.
        let at_estimate = cal.extensions.clone().unwrap();
        let com = payload_com_step(&model, &train, &options, &at_estimate, &cal).unwrap();
        let (_, obs0) = residuals(&at_estimate);
        let mut prob = KinematicProblem::new(&model, &obs0, cal.params.clone(), all.clone());
        prob.jacobian(&mut j);
        for c in 0..p {
            j.column_mut(c).scale_mut(cal.subspace.scales[c]);
        }
        a.columns_mut(0, r)
            .copy_from(&(&j * cal.subspace.v.columns(0, r)));
        for axis in 0..3 {
            let (mut plus, mut minus) = (at_estimate.clone(), at_estimate.clone());
            plus.payload_com_m[axis] += h;
            minus.payload_com_m[axis] -= h;
            let (rp, rm) = (residuals(&plus).0, residuals(&minus).0);
            for row in 0..m {
                a[(row, r + axis)] = (rp[row] - rm[row]) / (2.0 * h) * 1e-2;
            }
        }
        let ata = a.transpose() * &a;
        let joint = ata.clone().try_inverse().expect("AᵀA invertible");
        let known = ata
            .view((0, 0), (r, r))
            .clone_owned()
            .try_inverse()
            .expect("JᵀJ invertible");
        let dv = DMatrix::from_fn(p, r, |i, k| cal.subspace.scales[i] * cal.subspace.v[(i, k)]);
        let reference = &dv * (joint.view((0, 0), (r, r)) - known) * dv.transpose();
        let largest = reference.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = (&com.covariance_inflation - &reference)
            .iter()
            .fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(largest > 0.0);
        // Apart by the forward differences' truncation (5.9e-6 measured; the step's is 8e-5).
        assert!(
            diff < 1e-4 * largest,
            "inflation off the dense reference by {diff:e} of its largest entry {largest:e}"
        );
        // How much it matters: the largest share of a reported (inflated) variance it makes up.
        let grow = (0..p)
            .filter(|&i| cal.covariance[(i, i)] > 0.0)
            .map(|i| reference[(i, i)] * cal.report.variance_factor() / cal.covariance[(i, i)])
            .fold(0.0f64, f64::max);
        eprintln!(
            "inflation agrees to {:.1e}; up to {grow:.2} of a reported variance",
            diff / largest
        );
    }
}
