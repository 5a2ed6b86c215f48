//! `diagnose --report DIR`: plots of the residual against each cause's regressor before and after the
//! cause was adopted, error histograms, and a one-page summary (`index.html`, also `summary.md`), drawn
//! from the numbers the diagnosis keeps ([`calib::diagnose::report::PlotData`]).

use crate::error::CliError;
use calib::diagnose::Diagnosis;
use calib::diagnose::report::{PlotData, RegressorPlot};
use plot::{Plot, Series, Style, histogram_svg};
use sim::io::write_atomic;
use std::path::Path;

fn regressor_svg(p: &RegressorPlot) -> String {
    let pts = |y: &[f64]| {
        p.x.iter()
            .copied()
            .zip(y.iter().copied())
            .collect::<Vec<_>>()
    };
    let (lo, hi) =
        p.x.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
    let mut series = vec![
        Series {
            label: "partial residual (without this term)".into(),
            points: pts(&p.before),
            style: Style::Markers,
        },
        Series {
            label: "residual (cause adopted)".into(),
            points: pts(&p.after),
            style: Style::Markers,
        },
    ];
    if !p.curve.is_empty() {
        series.push(Series {
            label: "identified".into(),
            points: p.curve.clone(),
            style: Style::Dashed,
        });
    } else if lo.is_finite() && hi > lo {
        series.push(Series {
            label: "identified".into(),
            points: vec![(lo, p.slope * lo), (hi, p.slope * hi)],
            style: Style::Dashed,
        });
    }
    Plot {
        title: p.title.clone(),
        x_label: p.x_label.clone(),
        y_label: p.y_label.clone(),
        log_x: false,
        log_y: false,
        series,
    }
    .to_svg(720, 440)
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn um(x: f64) -> String {
    format!("{:.1} µm", x * 1e6)
}

/// The Markdown summary (also the text of the HTML page).
pub fn summary_markdown(d: &Diagnosis, data_name: &str) -> String {
    let mut s = format!(
        "# robocal diagnose: {} on {}\n\n{} training and {} test poses (split seed {}); noise floor {} ({}).\n\n",
        d.robot,
        data_name,
        d.n_train,
        d.n_test,
        d.seed,
        um(d.noise_floor_m),
        d.noise_floor_source
    );
    s.push_str("| model | train RMS | test RMS | test max |\n|---|---|---|---|\n");
    for st in &d.steps {
        s.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            st.model,
            um(st.train_rms_m),
            um(st.test_rms_m),
            um(st.test_max_m)
        ));
    }
    s.push_str("\n## Findings\n\n");
    if d.findings.is_empty() {
        s.push_str(
            "None: the kinematic model explains the data as well as any known cause would.\n",
        );
    }
    for f in &d.findings {
        let joints = if f.joints.is_empty() {
            String::new()
        } else {
            format!(" (joints {})", f.joint_list())
        };
        s.push_str(&format!(
            "- **{}**{joints}: {}. Test RMS {} → {} (gain {:.0} %, held-out z = {:.1}).\n",
            f.cause,
            f.evidence,
            um(f.test_rms_m_before),
            um(f.test_rms_m_after),
            100.0 * f.gain,
            f.test_z
        ));
    }
    if d.findings.iter().any(|f| f.rival.is_some()) {
        s.push_str(
            "\n## Rivals\n\nThe cause or probe that came closest when each finding was adopted.\n\n\
             | finding | nearest rival | its gain | finding's gain | why not the rival |\n|---|---|---|---|---|\n",
        );
        for f in &d.findings {
            if let Some(r) = &f.rival {
                s.push_str(&format!(
                    "| {} | {} | {:.1} % | {:.1} % | {} |\n",
                    f.cause,
                    r.name,
                    100.0 * r.gain,
                    100.0 * f.gain,
                    r.why_not
                ));
            }
        }
    }
    if !d.unexplained.rejected.is_empty() {
        s.push_str("\n## Rejected for impossible physics\n\n");
        for r in &d.unexplained.rejected {
            s.push_str(&format!("- **{}**: {}.\n", r.cause, r.evidence));
        }
    }
    if !d.trials.is_empty() {
        s.push_str(
            "\n## Candidates tried\n\nA cause passes when its training z and held-out z both pass \
             (Bonferroni over the round's candidates), it gains at least 2 % and no probe for an error \
             outside the known causes (an angle error of one joint periodic in its angle or linear in the \
             joint angles; not the harmonics a transmission error models) explains the residual as well; \
             of those passing, the one with the largest held-out z is adopted. The adopted causes are \
             then checked in their joint fit: one whose named parameters are physically impossible is \
             rejected and the rounds run again without it.\n\n\
             | round | cause | test RMS | gain | held-out z | training z | passes | explained as well by | impossible physics |\n\
             |---|---|---|---|---|---|---|---|---|\n",
        );
        for t in &d.trials {
            s.push_str(&format!(
                "| {} | {} | {} | {:.1} % | {:.1} | {:.1} | {} | {} | {} |\n",
                t.round,
                t.cause,
                um(t.test_rms_m),
                100.0 * t.gain,
                t.test_z,
                t.train_z,
                if t.significant { "yes" } else { "no" },
                t.beaten_by.as_deref().unwrap_or(""),
                t.impossible.as_deref().unwrap_or("")
            ));
        }
    }
    s.push_str(&format!(
        "\n## Unexplained\n\n{}: {}.\n\nModel for `calibrate --model auto`: `{}`.\n",
        if d.unexplained.present {
            "Present"
        } else {
            "None"
        },
        d.unexplained.note,
        d.model
    ));
    s
}

/// The files of a report whose names do not depend on the diagnosis (the plots of the causes are
/// `*.svg` besides).
pub const FIXED_FILES: [&str; 4] = ["index.html", "summary.md", "diagnosis.json", "errors.svg"];

/// True for a name the report writes (one of [`FIXED_FILES`] or a plot `*.svg`): what a new report
/// replaces in an old report's folder.
pub fn is_report_file(name: &str) -> bool {
    FIXED_FILES.contains(&name) || name.ends_with(".svg")
}

/// Writes the report into `dir` (created): `index.html`, `summary.md`, `diagnosis.json`, one SVG per
/// regressor plot and `errors.svg`. The files replace an earlier report as a whole
/// ([`sim::io::StagedDir`]: written into a staging folder beside `dir`, then moved in; files in `dir`
/// that a report does not write are kept). Returns the files written.
///
/// # Errors
/// A runtime [`CliError`] naming the folder or file that cannot be created or written.
pub fn write(
    dir: &Path,
    d: &Diagnosis,
    plots: &PlotData,
    data_name: &str,
) -> Result<Vec<String>, CliError> {
    let stage = sim::io::StagedDir::new(dir)?;
    let files = write_into(stage.path(), d, plots, data_name).map_err(|e| match e {
        Staged::Sim(e) => CliError::from(stage.user_error(e)),
        Staged::Cli(e) => e,
    })?;
    stage.commit(&is_report_file)?;
    Ok(files)
}

/// An error while writing into the staging folder.
enum Staged {
    /// A write that failed (its path is renamed to the user's folder).
    Sim(sim::SimError),
    /// Anything else.
    Cli(CliError),
}

impl From<sim::SimError> for Staged {
    fn from(e: sim::SimError) -> Self {
        Staged::Sim(e)
    }
}

impl From<CliError> for Staged {
    fn from(e: CliError) -> Self {
        Staged::Cli(e)
    }
}

/// Writes the report's files into the existing folder `dir`.
fn write_into(
    dir: &Path,
    d: &Diagnosis,
    plots: &PlotData,
    data_name: &str,
) -> Result<Vec<String>, Staged> {
    let mut files = Vec::new();
    let mut put = |name: &str, text: &str| -> Result<(), Staged> {
        write_atomic(&dir.join(name), text.as_bytes())?;
        files.push(name.to_string());
        Ok(())
    };
    let to_um = |v: &[f64]| v.iter().map(|x| x * 1e6).collect::<Vec<_>>();
    let final_model = d.model.name();
    let hist = histogram_svg(
        "Held-out position errors",
        "error (µm)",
        &[
            ("kinematic", &to_um(&plots.test_errors_kinematic_m)),
            (&final_model, &to_um(&plots.test_errors_final_m)),
        ],
        30,
        720,
        400,
    );
    put("errors.svg", &hist)?;
    let mut figures = vec![(
        "errors.svg".to_string(),
        "Held-out position errors".to_string(),
    )];
    for p in plots.regressors.iter().chain(plots.unexplained.iter()) {
        let name = format!("{}.svg", p.file);
        put(&name, &regressor_svg(p))?;
        figures.push((name, p.title.clone()));
    }
    let md = summary_markdown(d, data_name);
    let mut md_full = md.clone();
    md_full.push_str("\n## Plots\n\n");
    for (f, t) in &figures {
        md_full.push_str(&format!("![{t}]({f})\n\n"));
    }
    put("summary.md", &md_full)?;
    let json = serde_json::to_string_pretty(d)
        .map_err(|e| CliError::Runtime(format!("cannot write the diagnosis as JSON: {e}")))?;
    put("diagnosis.json", &json)?;
    let mut html = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>robocal diagnose</title>\
         <style>body{font-family:sans-serif;max-width:980px;margin:2em auto;line-height:1.4}\
         table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}\
         td:first-child{text-align:left}img{max-width:100%}</style></head><body>\n",
    );
    for line in md.lines() {
        let l = html_escape(line);
        if let Some(h) = l.strip_prefix("# ") {
            html.push_str(&format!("<h1>{h}</h1>\n"));
        } else if let Some(h) = l.strip_prefix("## ") {
            html.push_str(&format!("<h2>{h}</h2>\n"));
        } else if l.starts_with("|---") {
        } else if let Some(row) = l.strip_prefix('|') {
            let cells: Vec<&str> = row
                .trim_end_matches('|')
                .split('|')
                .map(str::trim)
                .collect();
            // The first row of a table is its header.
            let header = !html.ends_with("</tr>\n");
            let tag = if header { "th" } else { "td" };
            if header {
                html.push_str("<table>\n");
            }
            html.push_str("<tr>");
            for c in cells {
                html.push_str(&format!("<{tag}>{c}</{tag}>"));
            }
            html.push_str("</tr>\n");
        } else if l.is_empty() {
            if html.ends_with("</tr>\n") {
                html.push_str("</table>\n");
            }
        } else {
            let l = l.replace("**", "");
            html.push_str(&format!("<p>{}</p>\n", l.trim_start_matches("- ")));
        }
    }
    html.push_str("<h2>Plots</h2>\n");
    for (f, t) in &figures {
        html.push_str(&format!(
            "<figure><img src=\"{f}\" alt=\"{t}\"><figcaption>{t}</figcaption></figure>\n",
            t = html_escape(t)
        ));
    }
    html.push_str("</body></html>\n");
    put("index.html", &html)?;
    Ok(files)
}
