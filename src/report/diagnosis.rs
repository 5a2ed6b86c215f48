//! The diagnosis as a [`Document`], built once: `robocal diagnose` prints it as text on stderr, the
//! report writes it as `summary.md` and `index.html` (with its figures).

use crate::document::{Block, Document, Span, Table, text};
use calib::select::diagnose::Diagnosis;

/// A length in m as micrometres with one decimal: `12.3 µm`.
fn um(x: f64) -> String {
    format!("{:.1} µm", x * 1e6)
}

/// What the diagnosis could not try and why, in one line (without the `warning: ` of the terminal),
/// or `None` when every candidate cause was tried.
pub fn not_tried(d: &Diagnosis) -> Option<String> {
    if d.not_tried.is_empty() {
        return None;
    }
    let causes: Vec<String> = d
        .not_tried
        .iter()
        .map(|n| format!("{}: {}", n.cause, n.reason.replace(['\n', '\r'], " ")))
        .collect();
    Some(format!("not tried: {}", causes.join("; ")))
}

/// The document of diagnosis `d` of the table `data_name`; `figures` (file, caption) are the plots
/// written beside it (none for the terminal).
pub fn document(d: &Diagnosis, data_name: &str, figures: &[(String, String)]) -> Document {
    let mut doc = Document::default();
    doc.push(Block::Heading(
        1,
        format!("robocal diagnose: {} on {data_name}", d.robot),
    ));
    doc.push(Block::Paragraph(text(format!(
        "{} training and {} test poses (split seed {}); noise floor {} ({}).",
        d.n_train,
        d.n_test,
        d.seed,
        um(d.noise_floor_m),
        d.noise_floor_source
    ))));
    if let Some(s) = &d.screening {
        doc.push(Block::Paragraph(text(format!("Screening: {}", s.note))));
    }
    if let Some(w) = not_tried(d) {
        doc.push(Block::Warning(w));
    }
    let mut steps = Table::new(&["model", "train RMS", "test RMS", "test max"]);
    for st in &d.steps {
        steps.row(vec![
            st.model.to_string(),
            um(st.train_rms_m),
            um(st.test_rms_m),
            um(st.test_max_m),
        ]);
    }
    doc.push(Block::Table(steps));

    doc.push(Block::Heading(2, "Findings".into()));
    if d.findings.is_empty() {
        doc.push(Block::Paragraph(text(
            "None: the kinematic model explains the data as well as any known cause would.",
        )));
    } else {
        doc.push(Block::List(
            d.findings
                .iter()
                .map(|f| {
                    let joints = if f.joints.is_empty() {
                        String::new()
                    } else {
                        format!(" (joints {})", f.joint_list())
                    };
                    vec![
                        Span::Strong(f.cause.to_string()),
                        Span::Text(format!(
                            "{joints}: {}. Test RMS {} → {} (gain {:.0} %, held-out z = {:.1}).",
                            f.evidence,
                            um(f.test_rms_m_before),
                            um(f.test_rms_m_after),
                            100.0 * f.gain,
                            f.test_z
                        )),
                    ]
                })
                .collect(),
        ));
    }
    if d.findings.iter().any(|f| !f.parameters.is_empty()) {
        doc.push(Block::Heading(2, "Parameters of the findings".into()));
        doc.push(Block::Paragraph(text(
            "Each finding's identified parameters in the joint fit of every adopted cause, with their \
             standard deviations; z = value / σ.",
        )));
        let mut t = Table::new(&["finding", "parameter", "value", "σ", "z", "note"])
            .left(1)
            .left(5);
        for f in &d.findings {
            for p in &f.parameters {
                let determined = p.sigma.is_finite() && p.sigma > 0.0;
                let (sigma, z, note) = if determined {
                    let remark = f.cause.model().remark(p.unit, p.value);
                    (
                        format!("{:.1e} {}", p.sigma, p.unit),
                        format!("{:.1}", p.value / p.sigma),
                        remark
                            .trim()
                            .trim_start_matches('(')
                            .trim_end_matches(')')
                            .to_string(),
                    )
                } else {
                    ("—".into(), "—".into(), "not determined on its own".into())
                };
                t.row(vec![
                    f.cause.to_string(),
                    p.name.clone(),
                    format!("{:.3e} {}", p.value, p.unit),
                    sigma,
                    z,
                    note,
                ]);
            }
        }
        doc.push(Block::Table(t));
    }
    if d.findings.iter().any(|f| f.rival.is_some()) {
        doc.push(Block::Heading(2, "Rivals".into()));
        doc.push(Block::Paragraph(text(
            "The cause or probe that came closest when each finding was adopted.",
        )));
        let mut t = Table::new(&[
            "finding",
            "nearest rival",
            "its gain",
            "finding's gain",
            "why not the rival",
        ])
        .left(1)
        .left(4);
        for f in &d.findings {
            if let Some(r) = &f.rival {
                t.row(vec![
                    f.cause.to_string(),
                    r.name.to_string(),
                    format!("{:.1} %", 100.0 * r.gain),
                    format!("{:.1} %", 100.0 * f.gain),
                    r.why_not.to_string(),
                ]);
            }
        }
        doc.push(Block::Table(t));
    }
    if !d.joint_selection.is_empty() {
        doc.push(Block::Heading(2, "Joints dropped from a cause".into()));
        doc.push(Block::List(
            d.joint_selection
                .iter()
                .map(|s| {
                    vec![
                        Span::Strong(s.cause.to_string()),
                        Span::Text(format!(": {}.", s.evidence)),
                    ]
                })
                .collect(),
        ));
    }
    if !d.unexplained.rejected.is_empty() {
        doc.push(Block::Heading(
            2,
            "Rejected for impossible or implausible physics".into(),
        ));
        doc.push(Block::List(
            d.unexplained
                .rejected
                .iter()
                .map(|r| {
                    vec![
                        Span::Strong(r.cause.to_string()),
                        Span::Text(format!(": {}.", r.evidence)),
                    ]
                })
                .collect(),
        ));
    }
    if let Some(c) = &d.campaigns {
        doc.push(Block::Heading(2, "Held-out residual per campaign".into()));
        let mut t = Table::new(&[
            "campaign",
            "test poses",
            "RMS",
            "others' RMS",
            "z",
            "differs",
        ]);
        for r in &c.campaigns {
            t.row(vec![
                r.campaign.to_string(),
                r.n_test_poses.to_string(),
                um(r.test_rms_m),
                um(r.others_rms_m),
                format!("{:.1}", r.z),
                if r.differs { "yes" } else { "no" }.into(),
            ]);
        }
        doc.push(Block::Table(t));
        doc.push(Block::Paragraph(text(c.note.to_string())));
    }
    if !d.trials.is_empty() {
        doc.push(Block::Heading(2, "Candidates tried".into()));
        doc.push(Block::Paragraph(text(
            "A cause passes when its training z and held-out z both pass (Bonferroni over the \
             round's candidates), it gains at least 2 % and no probe for an error outside the known \
             causes (an angle error of one joint periodic in its angle or linear in the joint angles; \
             not the harmonics a transmission error models) explains the residual as well; of those \
             passing, the one with the largest held-out z is adopted. The adopted causes are then \
             checked in their joint fit: one whose named parameters are physically impossible is \
             rejected and the rounds run again without it.",
        )));
        let mut t = Table::new(&[
            "round",
            "cause",
            "test RMS",
            "gain",
            "held-out z",
            "training z",
            "passes",
            "explained as well by",
            "impossible or implausible physics",
        ])
        .left(1)
        .left(7)
        .left(8);
        for tr in &d.trials {
            t.row(vec![
                tr.round.to_string(),
                match &tr.fitted_joints {
                    Some(js) => format!(
                        "{}@{}",
                        tr.cause,
                        js.iter()
                            .map(|j| j.to_string())
                            .collect::<Vec<_>>()
                            .join(",")
                    ),
                    None => tr.cause.to_string(),
                },
                um(tr.test_rms_m),
                format!("{:.1} %", 100.0 * tr.gain),
                format!("{:.1}", tr.test_z),
                format!("{:.1}", tr.train_z),
                if tr.significant { "yes" } else { "no" }.into(),
                tr.beaten_by.clone().unwrap_or_default(),
                tr.impossible.clone().unwrap_or_default(),
            ]);
        }
        doc.push(Block::Table(t));
    }
    doc.push(Block::Heading(2, "Unexplained".into()));
    doc.push(Block::Paragraph(text(format!(
        "{}: {}.",
        if d.unexplained.present {
            "Present"
        } else {
            "None"
        },
        d.unexplained.note
    ))));
    doc.push(Block::Paragraph(vec![
        Span::Text("Model for ".into()),
        Span::Code("calibrate --model auto".into()),
        Span::Text(": ".into()),
        Span::Code(d.model.to_string()),
        Span::Text(".".into()),
    ]));
    if !figures.is_empty() {
        doc.push(Block::Heading(2, "Plots".into()));
        for (file, caption) in figures {
            doc.push(Block::Figure {
                file: file.clone(),
                caption: caption.clone(),
            });
        }
    }
    doc
}
