//! Leave-one-region-out validation by Gauss–Newton steps from the fit on every row.
//!
//! A region's fit, started at the fit on every row (`all`), moves it by the change that leaving the
//! region's rows out makes: a small step. A Gauss–Newton step from `all` takes it: with the region's
//! rows left out, the other rows' scaled gradient `g = D Jᵀr` and the `R` factor of their scaled
//! Jacobian `J D` at `all` (one pass over every row, the regions' shares summed as
//! [`super::groups::fold_shares`] sums them) give `δ = −D Vᵣ Σᵣ⁻² Vᵣᵀ g`, in the identifiable
//! subspace of the SVD `J D = U Σ Vᵀ` of those rows (the rank decision of the fit,
//! [`Subspace::from_factor`]). Further steps, each from a pass over the training rows where the last
//! ended, take up the residuals' curvature until one is at most [`LAST_STEP`] of the first (in
//! standard deviations of the fit), which is then the last: one step alone misses the full fits' RMS
//! by 0.1 to 1.5 %, these by 10⁻⁷ to 10⁻⁵ (see the test; usually two steps, three or four with
//! residuals of millimetres). Steps that do not converge within [`MAX_STEPS`] (the undamped step
//! runs along a weakly determined direction, where the fit's damped iterations stop elsewhere: the
//! WAM's 2 mm residuals with compliance, `calib/tests/real_data.rs`) make the function decline, and
//! the caller fits the regions in full. The region's rows are then predicted as a region's fit would
//! predict them ([`held_out_errors`]). The cost: one pass over every row that the regions share, then
//! one or a few over each region's training rows, against the tens of passes of a fit (its
//! base-and-target fit, its iterations, its equilibrium refits).
//!
//! With joint compliance the torques of the first step are those of `all`'s equilibrium; each further
//! step evaluates them where the last one put the links ([`Regressors::build`]), as a fit's
//! equilibrium refits do (kept at `all`'s, the steps missed the full fits by up to 1.1e-5 of the RMS;
//! re-evaluated, by 6e-7).
//!
//! What stays as `all` has it:
//! - the rows `all` excluded as gross errors stay excluded, and no new ones are searched for.
//!
//! It stands for the `k` full fits of [`super::validate_by_region`] where only the held-out RMS is
//! wanted and is compared between models (diagnose's transfer test): the test in this module holds
//! it to the full fits' RMS. Not for a robust loss (its weights move with the step) or a learned
//! correction (refitted per region): [`region_rms_gauss_newton`] then says `None`.

#[allow(unused_imports)]
use super::*;
use crate::lm::Subspace;
use crate::model::extensions::Regressors;

/// The leave-one-region-out RMS (m) of the physical model of `all` (`request`'s model fitted on every
/// row of `data`) over `k` regions drawn with `seed` ([`region_of_rows`]), each region predicted
/// after Gauss–Newton steps from `all` with its rows left out (see the module). `Ok(None)` where the
/// steps do not stand for a fit: a robust loss, a learned correction, `all` fitted on other
/// campaigns than `data` has, or steps that do not converge for some region. Errors as [`super::validate_by_region`]'s when `data` cannot be split
/// into `k` regions.
pub fn region_rms_gauss_newton(
    model: &Model,
    data: &Dataset<'_>,
    request: &FitRequest<'_>,
    k: usize,
    seed: u64,
    all: &Calibration,
) -> Result<Option<f64>> {
    let options = request.options();
    if options.robust.is_some() || request.model().learned.is_some() || all.learned.is_some() {
        return Ok(None);
    }
    let keys = pose_keys(data);
    check_groups(data, &keys, k, "--regions", REGIONS_NEED)?;
    let region_of = region_of_rows(data, k, seed);
    let mut obs = observations(
        model,
        data,
        options,
        all.extensions.as_ref(),
        Some(&all.params),
    )?;
    if obs.campaign_indices(&all.params).is_err() || obs.ext.len() != all.params.extension.len() {
        return Ok(None);
    }
    // The gross errors of the fit on every row stay out (weight 0).
    for o in &all.report.excluded {
        if let Some(r) = obs.source_row.iter().position(|&s| s + 1 == o.row) {
            obs.weight[r] = 0.0;
        }
    }
    // The region of every observation row (a table row of `data`).
    let index_of: std::collections::HashMap<usize, usize> =
        data.rows.iter().enumerate().map(|(i, &r)| (r, i)).collect();
    let group: Vec<usize> = obs
        .source_row
        .iter()
        .map(|r| region_of[index_of[r]])
        .collect();
    let layout = ParamLayout::for_params(model, &all.params, obs.ext.params.clone());
    let p = layout.len();
    let scales = options.scales.vector(&layout);
    let mut problem = KinematicProblem::new(model, &obs, all.params.clone(), (0..p).collect());
    let parts = problem.group_parts(scales.as_slice(), &group, k);
    crate::cancel::checkpoint()?;
    let dim = obs.dim();
    // The step and its length in standard deviations of the fit (noise model units).
    let solve = |gradient: &[f64], factors: &[DMatrix<f64>], m: usize| {
        let sub = Subspace::from_factor(
            &crate::linalg::stacked_r_factor(factors, p),
            scales.as_slice(),
            options.lm.rank_rtol,
            options.lm.min_singular_value,
            m,
        );
        let step = gauss_newton_step(&sub, gradient);
        let length = sub.step_in_sigmas(&step, 1.0);
        (step, length)
    };
    let errors: Vec<Result<Option<Vec<Vector3<f64>>>>> = crate::cancel::relayed(|relay| {
        (0..k)
            .into_par_iter()
            .map(|f| {
                relay.run(|| {
                    let (_, test, _) = fold_rows(data, &region_of, f);
                    if test.is_empty() {
                        return Ok(Some(Vec::new()));
                    }
                    let m = group.iter().filter(|&&g| g != f).count() * dim;
                    // The first step from the other regions' shares of the pass at `all`.
                    let mut gradient = vec![0.0; p];
                    let mut factors: Vec<DMatrix<f64>> = Vec::new();
                    for (_, part) in parts.iter().enumerate().filter(|(g, _)| *g != f) {
                        for (t, v) in gradient.iter_mut().zip(&part.gradient) {
                            *t += v;
                        }
                        factors.extend(part.factors.iter().cloned());
                    }
                    let (mut step, first_length) = solve(&gradient, &factors, m);
                    let mut params = all.params.clone();
                    // Further steps from passes over the training rows where the last ended, until
                    // one is a small correction of the first. Otherwise (a weakly determined
                    // direction that the undamped steps take ever further, where the fit's damped
                    // iterations stop elsewhere) the region is fitted in full.
                    let training: Vec<usize> = group.iter().map(|&g| usize::from(g == f)).collect();
                    let mut converged = first_length < 1e-6;
                    for _ in 1..MAX_STEPS {
                        if converged {
                            break;
                        }
                        params.retract(&layout, &step);
                        // Torques where the step put the robot and the links, as a fit's
                        // equilibrium refits evaluate them.
                        let stepped;
                        let obs = match all.extensions.as_ref() {
                            Some(s) if s.needs_equilibrium() => {
                                let mut o = obs.clone();
                                o.ext = Regressors::build(
                                    model,
                                    s,
                                    data.table,
                                    &data.rows,
                                    &data.name,
                                    Some(&params),
                                )?;
                                stepped = o;
                                &stepped
                            }
                            _ => &obs,
                        };
                        let mut at =
                            KinematicProblem::new(model, obs, params.clone(), (0..p).collect());
                        let part = at
                            .group_parts(scales.as_slice(), &training, 2)
                            .swap_remove(0);
                        let (next, length) = solve(&part.gradient, &part.factors, m);
                        step = next;
                        converged = length <= LAST_STEP * first_length || length < 1e-6;
                    }
                    if !converged {
                        return Ok(None);
                    }
                    params.retract(&layout, &step);
                    let mut cal = all.clone();
                    cal.params = params;
                    cal.physical = None;
                    let test_set = data.part(
                        test.iter().map(|&i| data.rows[i]).collect(),
                        Part::RegionHeldOut(f),
                    );
                    Ok(Some(held_out_errors(model, &cal, &test_set, options)?.1))
                })
            })
            .collect()
    });
    let mut sum2 = 0.0;
    let mut n = 0usize;
    for e in errors {
        let Some(e) = e? else {
            return Ok(None);
        };
        sum2 += e.iter().map(|e| e.norm_squared()).sum::<f64>();
        n += e.len();
    }
    Ok((n > 0).then(|| (sum2 / n as f64).sqrt()))
}

/// Most Gauss–Newton steps per region before it is fitted in full instead.
pub const MAX_STEPS: usize = 6;

/// The steps have reached the region's minimum when one is at most this fraction of the first
/// (each in standard deviations of the fit), and is then the last: Gauss–Newton converges fast
/// where the residuals are close to linear (on the iiwa 7 the second step is 1-50 % of the first,
/// and after it the RMS moves by 10⁻⁵ of itself).
pub const LAST_STEP: f64 = 0.1;

/// The Gauss–Newton step (physical units) `δ = −D Vᵣ Σᵣ⁻² Vᵣᵀ g` for the scaled gradient
/// `g = D Jᵀr`, in the identifiable subspace of `sub`.
fn gauss_newton_step(sub: &Subspace, gradient: &[f64]) -> Vec<f64> {
    let p = sub.n_params();
    let mut step = vec![0.0; p];
    for c in 0..sub.rank {
        let s = sub.singular_values[c];
        let along: f64 = (0..p).map(|k| sub.v[(k, c)] * gradient[k]).sum::<f64>() / (s * s);
        for (k, d) in step.iter_mut().enumerate() {
            *d -= sub.scales[k] * sub.v[(k, c)] * along;
        }
    }
    step
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::spec::ModelSpec;
    use sim::scenario::{Overrides, Scenario};

    fn data_with(effects: &str, seed: u64) -> (Model, sim::measurement_table::MeasurementTable) {
        let text = format!(
            "{}\n{effects}",
            include_str!("../../../scenarios/iiwa7_kinematic.toml")
        );
        let sc = Scenario::parse(&text, "gauss_newton", std::path::Path::new(".")).unwrap();
        let res = sc
            .resolve(&Overrides {
                seed: Some(seed),
                poses: Some(200),
                noise: None,
            })
            .unwrap();
        let dir = std::env::temp_dir().join(format!(
            "robocal_gauss_newton_{}_{seed}",
            std::process::id()
        ));
        sim::generate::generate(&res, &dir, None).unwrap();
        let table = sim::measurement_table::read(&dir.join("measurements.parquet")).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        (res.model, table)
    }

    /// The steps' RMS against the full region fits' (each an iterated fit started at `all`, its own
    /// rank decision, equilibrium and gross-error search), for a kinematic model with an error it
    /// does not model (so that leaving a region out moves the fit: 0.27 and 2.4 mm held out) and for a
    /// compliance model with its equilibrium and an error it does not model. Measured: they agree to
    /// 5.8e-7 to 2.6e-6 of the RMS (one step alone: 0.14 to 1.5 %, growing with the residuals, as the
    /// neglected curvature does); the test allows 1e-3.
    #[test]
    fn steps_match_the_full_region_fits() {
        let cases = [
            (
                "[effects.compliance]\nstiffness_nm_per_rad = [inf, 9e4, inf, 6e4, inf, inf, inf]\n",
                "kinematic",
            ),
            (
                "[effects.compliance]\nstiffness_nm_per_rad = [inf, 9e3, inf, 6e3, inf, inf, inf]\n",
                "kinematic",
            ),
            (
                "[effects.compliance]\nstiffness_nm_per_rad = [inf, 9e3, inf, 6e3, inf, inf, inf]\n\
                 [effects.coupling]\npairs = [[2, 4]]\nratio_rad_per_rad = [3e-4]\n",
                "kinematic+joint_compliance",
            ),
        ];
        for (k, (effects, spec)) in cases.iter().enumerate() {
            let (model, table) = data_with(effects, 11 + k as u64);
            let rows: Vec<usize> = (0..table.len()).collect();
            let data = Dataset::new(&table, rows, "gauss_newton", Part::All);
            let options = CalibrationOptions::default();
            let spec = ModelSpec::parse(spec).unwrap();
            let request = FitRequest::new(&spec, &options);
            let all = fit(&model, &data, &request).unwrap();
            let full = validate_by_region(&model, &data, &request, 5, 3, Some(&all))
                .unwrap()
                .final_stats()
                .rms_m;
            let one = region_rms_gauss_newton(&model, &data, &request, 5, 3, &all)
                .unwrap()
                .expect("a physical model without a robust loss");
            let rel = (one - full).abs() / full;
            eprintln!(
                "{}: steps against full fits {rel:.1e} of the RMS",
                spec.name()
            );
            assert!(
                rel < 1e-3,
                "{}: steps {:.3} µm, full fits {:.3} µm ({:.2} %)",
                spec.name(),
                one * 1e6,
                full * 1e6,
                100.0 * rel
            );
            // Leaving regions out does move the fit: the held-out RMS is not that of `all` itself.
            let (_, at_all, _) = held_out_errors(&model, &all, &data, &options).unwrap();
            let rms_all =
                (at_all.iter().map(|e| e.norm_squared()).sum::<f64>() / at_all.len() as f64).sqrt();
            assert!(
                one > 1.02 * rms_all,
                "{}: held-out {:.3} µm against {:.3} µm on the fitted rows",
                spec.name(),
                one * 1e6,
                rms_all * 1e6
            );
        }
    }

    /// The step is the least-squares solution in the identifiable subspace: for a linear problem
    /// `r = J x − y` at `x = 0` it is `J⁺ y`, and a direction below the rank threshold gets none.
    #[test]
    fn gauss_newton_step_is_the_truncated_least_squares_solution() {
        let j = DMatrix::from_row_slice(
            4,
            3,
            &[1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0],
        );
        let y = nalgebra::DVector::from_vec(vec![1.0, 2.0, 3.0, 4.0]);
        let scales = [0.5, 2.0, 1.0];
        let sub = Subspace::analyze(&j, &scales, 1e-8, 0.0);
        assert_eq!(sub.rank, 2, "the third column is empty");
        // g = D Jᵀ r with r = −y at x = 0.
        let jt_r = j.transpose() * (-&y);
        let g: Vec<f64> = jt_r.iter().zip(&scales).map(|(v, s)| v * s).collect();
        let step = gauss_newton_step(&sub, &g);
        let x = j.clone().pseudo_inverse(1e-12).unwrap() * &y;
        for c in 0..3 {
            assert!((step[c] - x[c]).abs() < 1e-12, "{step:?} against {x}");
        }
    }
}
