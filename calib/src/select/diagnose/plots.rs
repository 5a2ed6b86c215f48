//! The numbers of the report's plots of a finding (the rendering is the command line's).

#[allow(unused_imports)]
use super::*;

/// Smallest lever `|∂p/∂qⱼ|` (m/rad) of a row to be drawn in a joint-angle residual plot: below it the
/// projection amplifies the noise more than it shows.
pub(super) const MIN_PLOT_LEVER_M: f64 = 0.15;

/// The residual `−err` of each test row of `current` as the angle of joint `j` (µrad) that would
/// explain it (NaN, not drawn, where the joint's lever is below [`MIN_PLOT_LEVER_M`]).
pub(super) fn as_joint_angle_urad(
    model: &Model,
    split: &Split<'_>,
    current: &Evaluated,
    err: &[Vector3<f64>],
    j: usize,
) -> Vec<f64> {
    let n = model.nq();
    let dirs = current.test_directions(model, split);
    err.iter()
        .enumerate()
        .map(|(k, e)| {
            let d = dirs[k * n + j];
            let n2 = d.norm_squared();
            if n2 >= MIN_PLOT_LEVER_M * MIN_PLOT_LEVER_M {
                -e.dot(&d) / n2 * 1e6
            } else {
                f64::NAN
            }
        })
        .collect()
}

/// Plots of a finding: per named joint (and the growth), against the parameter's regressor, the
/// partial residual (the adopted model's residual plus this term's own contribution: what the data
/// show of the term) and the adopted model's residual. A joint with several joint-angle parameters of
/// the cause (the harmonics of a transmission error) is drawn against its angle, with the identified
/// curve; a bending parameter as the residual's rotation about its axis, against the bending moment.
pub(super) fn finding_plots(
    model: &Model,
    split: &Split<'_>,
    after: &Evaluated,
    cause: Cause,
    joints: &[usize],
    growth: bool,
) -> Vec<report::RegressorPlot> {
    let layout = &after.cal.layout;
    let n_test = split.test.rows.len();
    let regressor =
        |e: usize| -> Vec<f64> { (0..n_test).map(|r| after.test_regs.row(r)[e]).collect() };
    let mut out = Vec::new();
    for &j in joints {
        let angle_params: Vec<usize> = (0..layout.extensions.len())
            .filter(|&e| {
                let p = &layout.extensions[e];
                p.cause == cause && p.term == Term::JointAngle { joint: j - 1 }
            })
            .collect();
        if angle_params.is_empty() {
            continue;
        }
        let resid = as_joint_angle_urad(model, split, after, &after.test_err, j - 1);
        // This joint's angle change by the cause per test row (µrad).
        let contribution: Vec<f64> = (0..n_test)
            .map(|r| {
                angle_params
                    .iter()
                    .map(|&e| after.cal.params.extension[e] * after.test_regs.row(r)[e] * 1e6)
                    .sum()
            })
            .collect();
        let before: Vec<f64> = resid
            .iter()
            .zip(&contribution)
            .map(|(r, c)| r + c)
            .collect();
        let base = report::RegressorPlot {
            file: format!("{}_joint{j}", cause.name()),
            title: format!("{}: joint {j}", cause.name()),
            y_label: format!("residual as joint {j} angle (µrad)"),
            before,
            after: resid,
            ..Default::default()
        };
        if let [e] = angle_params[..] {
            let axis = cause.model().plot_axis(layout.extensions[e].term);
            out.push(report::RegressorPlot {
                x_label: axis.label,
                x: regressor(e).iter().map(|v| axis.sign * v).collect(),
                slope: axis.sign * after.cal.params.extension[e] * 1e6,
                ..base
            });
        } else {
            let q: Vec<f64> = split
                .test
                .rows
                .iter()
                .map(|&r| split.test.table.q_row(r)[j - 1])
                .collect();
            let mut curve: Vec<(f64, f64)> = q.iter().copied().zip(contribution).collect();
            curve.sort_by(|a, b| a.0.total_cmp(&b.0));
            out.push(report::RegressorPlot {
                x_label: cause
                    .model()
                    .plot_axis(Term::JointAngle { joint: j - 1 })
                    .label,
                x: q,
                curve,
                ..base
            });
        }
    }
    let prediction = Prediction::new(model, &after.cal.params);
    let mut scratch = prediction.scratch();
    for (e, p) in layout.extensions.iter().enumerate() {
        if p.cause != cause {
            continue;
        }
        let value = after.cal.params.extension[e];
        let g = regressor(e);
        match p.term {
            Term::Bend { joint, about } if joints.contains(&(joint + 1)) => {
                // Every parameter of this bending axis (a robot without masses has several lumped
                // products per axis); drawn once, at the axis's first.
                let same: Vec<usize> = (0..layout.extensions.len())
                    .filter(|&k| {
                        layout.extensions[k].cause == cause && layout.extensions[k].term == p.term
                    })
                    .collect();
                if same.first() != Some(&e) {
                    continue;
                }
                // The residual as the rotation about this bending axis that would explain it (µrad).
                let local = Vector3::ith(about, 1.0);
                let resid: Vec<f64> = (0..n_test)
                    .map(|r| {
                        let q = split.test.table.q_row(split.test.rows[r]);
                        prediction.physical(&after.test_regs, r, q, &mut scratch);
                        let s = &scratch;
                        let (w, o) =
                            prediction
                                .chain()
                                .bend_axis(&s.chain, joint, &local, &s.bend[joint]);
                        let d = w.cross(&(s.chain.p_tracker - o));
                        let n2 = d.norm_squared();
                        if n2 >= MIN_PLOT_LEVER_M * MIN_PLOT_LEVER_M {
                            -after.test_err[r].dot(&d) / n2 * 1e6
                        } else {
                            f64::NAN
                        }
                    })
                    .collect();
                // One compliance: against the bending moment, with the compliance as the slope.
                // Several products: against the identified bend (µrad), with slope one.
                let (x_label, x, slope) = if let [only] = same[..] {
                    let axis = cause.model().plot_axis(p.term);
                    let x: Vec<f64> = g.iter().map(|v| axis.sign * v).collect();
                    (
                        axis.label,
                        x,
                        axis.sign * after.cal.params.extension[only] * 1e6,
                    )
                } else {
                    let bend: Vec<f64> = (0..n_test)
                        .map(|r| {
                            same.iter()
                                .map(|&k| {
                                    after.cal.params.extension[k] * after.test_regs.row(r)[k] * 1e6
                                })
                                .sum()
                        })
                        .collect();
                    (
                        format!(
                            "identified bend of joint {} about {} (µrad)",
                            joint + 1,
                            crate::model::extensions::axis_name(about)
                        ),
                        bend,
                        1.0,
                    )
                };
                let before: Vec<f64> = resid.iter().zip(&x).map(|(r, x)| r + slope * x).collect();
                out.push(report::RegressorPlot {
                    file: format!(
                        "{}_joint{}_{}",
                        cause.name(),
                        joint + 1,
                        crate::model::extensions::axis_name(about)
                    ),
                    title: format!(
                        "{}: joint {} about {}",
                        cause.name(),
                        joint + 1,
                        crate::model::extensions::axis_name(about)
                    ),
                    x_label,
                    y_label: format!(
                        "residual as bending of joint {} about {} (µrad)",
                        joint + 1,
                        crate::model::extensions::axis_name(about)
                    ),
                    x,
                    before,
                    after: resid,
                    slope,
                    curve: Vec::new(),
                });
            }
            Term::Growth if growth => {
                let t = after.cal.params.t_tracker_base.translation.vector;
                let rel = |err: &[Vector3<f64>]| -> Vec<f64> {
                    split
                        .test
                        .rows
                        .iter()
                        .zip(err)
                        .map(|(&r, e)| {
                            let lever = Vector3::from(split.test.table.position[r]) - t;
                            -e.dot(&lever) / lever.norm_squared() * 1e6
                        })
                        .collect()
                };
                out.push(report::RegressorPlot {
                    file: format!("{}_growth", cause.name()),
                    title: format!("{}: link growth", cause.name()),
                    x_label: cause.model().plot_axis(p.term).label,
                    y_label: "residual as growth (ppm)".into(),
                    before: rel(&after.test_err)
                        .iter()
                        .zip(&g)
                        .map(|(r, g)| r + value * g * 1e6)
                        .collect(),
                    after: rel(&after.test_err),
                    x: g,
                    slope: value * 1e6,
                    curve: Vec::new(),
                });
            }
            _ => {}
        }
    }
    out
}
