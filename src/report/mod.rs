//! `diagnose --report DIR`: plots of the residual against each cause's regressor before and after the
//! cause was adopted, error histograms, and a one-page summary (`index.html`, also `summary.md`), drawn
//! from the numbers the diagnosis keeps ([`calib::select::diagnose::report::PlotData`]). The summary is the
//! diagnosis document of [`diagnosis`], the same one `robocal diagnose` prints as text.

pub mod diagnosis;

use crate::error::CliError;
use calib::select::diagnose::Diagnosis;
use calib::select::diagnose::report::{PlotData, RegressorPlot};
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
    let doc = diagnosis::document(d, data_name, &figures);
    put("summary.md", &doc.to_markdown())?;
    let json = serde_json::to_string_pretty(d)
        .map_err(|e| CliError::Runtime(format!("cannot write the diagnosis as JSON: {e}")))?;
    put("diagnosis.json", &json)?;
    put(
        "index.html",
        &doc.to_html(&format!("robocal diagnose: {} on {data_name}", d.robot)),
    )?;
    Ok(files)
}
