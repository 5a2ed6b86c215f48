//! Diagnosis of a measurement stream too large to hold: a seeded sample of whole poses diagnosed in
//! memory, and the rest of the file predicted in pieces by the models the diagnosis compares.
//!
//! Diagnose decides which causes the data show. Its decisions rest on a held-out test whose power
//! saturates long before 10⁷ rows: the candidates are already screened on a few thousand poses
//! ([`super::screening`]). What a stream adds is a held-out set nobody could fit on. So:
//!
//! 1. **Count** the rows (one pass).
//! 2. **Sample** whole poses: a pose is taken when a seeded hash of its campaign and pose id
//!    ([`pose_hash`]) falls below `sample_rows / rows` of the hash range. The same poses whatever
//!    the piece size, all rows of a pose or none, about `sample_rows` rows.
//! 3. **Diagnose** the sample in memory ([`super::diagnose_with_progress`]): every step of the
//!    in-memory diagnosis, on the sample's poses.
//! 4. **Fit** the kinematic model and the model the diagnosis adopts on every pose of the sample.
//! 5. **Predict the rest**: every row of the poses not sampled, by both fits, in pieces
//!    ([`crate::validate::held_out_errors`]), summed row by row ([`HeldOutSum`]). This is the gain
//!    on poses neither the diagnosis nor the fits saw, on as many rows as the file has.
//!
//! Memory is the sample's diagnosis and one piece; time grows with the rows only through the three
//! passes. The report says what came from the sample and what from every row.

use super::{DiagnoseOptions, Diagnosis, diagnose_with_progress};
use crate::error::{CalibError, Result};
use crate::fit::stream::ChunkSource;
use crate::fit::stream::pass::in_file;
use crate::fit::stream::scan::pose_hash;
use crate::fit::{Calibration, Dataset, FitRequest, Part, fit};
use crate::model::spec::ModelSpec;
use crate::validate::{HeldOutStats, HeldOutSum, held_out_errors};
use sim::Model;

/// Rows of the sample a streamed diagnosis takes by default: 100,000 (the in-memory diagnosis of
/// 100,000 rows of `iiwa7_all` takes about 13 s and 430 MB on the 2-core machine).
pub const DEFAULT_SAMPLE_ROWS: usize = 100_000;

/// Salt of the sample's hash, so that it is not the streamed validation's folds.
const SAMPLE_SALT: u64 = 0x6469_6167_6e6f_7365;

/// The models' errors on the rows the diagnosis did not see.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RestOfStream {
    /// Rows predicted: every row of a pose not in the sample.
    pub rows: usize,
    /// The model the diagnosis adopts (its name).
    pub model: String,
    /// The nominal robot, base and target fitted on the sample.
    pub nominal: HeldOutStats,
    /// The kinematic model fitted on the sample.
    pub kinematic: HeldOutStats,
    /// The adopted model fitted on the sample (its learned correction included, when it has one).
    pub adopted: HeldOutStats,
    /// `1 − adopted RMS / kinematic RMS`: the adopted model's gain on the rest of the stream.
    pub gain: f64,
}

/// A streamed diagnosis: the sample's diagnosis and the rest of the file predicted.
#[derive(Clone, Debug)]
pub struct StreamedDiagnosis {
    /// The diagnosis of the sample.
    pub diagnosis: Diagnosis,
    /// Rows of the file.
    pub rows: usize,
    /// Rows of the sample.
    pub sample_rows: usize,
    /// Passes over the file.
    pub passes: usize,
    /// The rest of the file, predicted (`None` when the sample is the whole file).
    pub rest: Option<RestOfStream>,
}

impl StreamedDiagnosis {
    /// The JSON `stream` object: rows, sample rows, passes and the rest of the stream.
    pub fn json(&self, chunk_rows: usize) -> serde_json::Value {
        serde_json::json!({
            "rows": self.rows,
            "sample_rows": self.sample_rows,
            "passes": self.passes,
            "chunk_rows": chunk_rows,
            "rest": self.rest,
        })
    }

    /// The report's lines on the stream.
    pub fn text(&self) -> String {
        let mut s = format!(
            "streamed: diagnosed on a seeded sample of whole poses, {} of {} rows; every figure above \
             comes from the sample\n",
            self.sample_rows, self.rows
        );
        if let Some(r) = &self.rest {
            let mm = |v: f64| format!("{:.4} mm", v * 1e3);
            s.push_str(&format!(
                "the rest of the stream ({} rows of poses no fit saw), predicted by models fitted on the \
                 sample: nominal {} RMS, kinematic {} RMS, {} {} RMS ({:.1} % below kinematic)\n",
                r.rows,
                mm(r.nominal.rms_m),
                mm(r.kinematic.rms_m),
                r.model,
                mm(r.adopted.rms_m),
                100.0 * r.gain
            ));
        }
        s
    }
}

/// Whether the pose (campaign, pose id) is in the sample of a streamed diagnosis with seed `seed`
/// that takes `fraction` of the hash range (`sample_rows / rows`).
pub fn in_sample(seed: u64, fraction: f64, campaign: i64, pose: i64) -> bool {
    if fraction >= 1.0 {
        return true;
    }
    let h = pose_hash(seed ^ SAMPLE_SALT, campaign, pose);
    (h as f64) < fraction * (u64::MAX as f64)
}

/// Diagnoses the rows of `source` through a seeded sample of about `sample_rows` rows of whole poses
/// (module docs); `options` as for the in-memory diagnosis (its seed also draws the sample).
/// `progress` hears each pass's rows and each fit. Errors: an empty file, a sample the diagnosis
/// refuses (too few poses), a bad row (named by its row of the file).
pub fn diagnose_streamed(
    model: &Model,
    source: &dyn ChunkSource,
    options: &DiagnoseOptions,
    sample_rows: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<StreamedDiagnosis> {
    let name = source.name().to_string();
    // 1. Count.
    let mut rows = 0;
    let mut columns = None;
    for chunk in source.pass()? {
        crate::cancel::checkpoint()?;
        let chunk = chunk?;
        columns.get_or_insert_with(|| chunk.table.empty_like(0));
        rows += chunk.table.len();
        progress(&format!("reading {name}: {rows} rows"));
    }
    let Some(empty) = columns.filter(|_| rows > 0) else {
        return Err(CalibError::BadValue {
            context: name,
            field: "rows".into(),
            value: "0".into(),
            problem: "no rows to diagnose".into(),
        });
    };
    // 2. Sample whole poses.
    let fraction = sample_rows as f64 / rows as f64;
    let seed = options.seed;
    let mut sample = empty;
    let mut done = 0;
    for chunk in source.pass()? {
        crate::cancel::checkpoint()?;
        let chunk = chunk?;
        let t = &chunk.table;
        for r in 0..t.len() {
            let (c, p) = t.pose_key(r);
            if in_sample(seed, fraction, c, p) {
                sample.push_row(&t.row(r))?;
            }
        }
        done += t.len();
        progress(&format!("sampling {name}: {done} rows"));
    }
    let sample_name = format!("{name} (a sample of {} rows)", sample.len());
    // 3. Diagnose the sample.
    let diagnosis = diagnose_with_progress(model, &sample, &sample_name, options, progress)?;
    let mut passes = 2;
    if sample.len() == rows {
        return Ok(StreamedDiagnosis {
            diagnosis,
            rows,
            sample_rows: sample.len(),
            passes,
            rest: None,
        });
    }
    // 4. Both models on every pose of the sample.
    let all = Dataset::all(&sample, &sample_name);
    let calibration = &options.calibration;
    progress("fitting kinematic on the sample");
    let kinematic = fit(
        model,
        &all,
        &FitRequest::new(&ModelSpec::kinematic(), calibration),
    )?;
    let adopted_name = diagnosis.model.name();
    progress(&format!("fitting {adopted_name} on the sample"));
    let adopted = if diagnosis.model == ModelSpec::kinematic() {
        kinematic.clone()
    } else {
        fit(model, &all, &FitRequest::new(&diagnosis.model, calibration))?
    };
    drop(all);
    drop(sample);
    // 5. The rest.
    let mut sums: [HeldOutSum; 3] = Default::default();
    let mut predicted = 0;
    let mut done = 0;
    let final_errors = |cal: &Calibration, test: &Dataset<'_>| -> Result<Vec<_>> {
        let (_, after, learned) = held_out_errors(model, cal, test, calibration)?;
        Ok(learned.unwrap_or(after))
    };
    for chunk in source.pass()? {
        crate::cancel::checkpoint()?;
        let chunk = chunk?;
        let t = &chunk.table;
        let rest: Vec<usize> = (0..t.len())
            .filter(|&r| {
                let (c, p) = t.pose_key(r);
                !in_sample(seed, fraction, c, p)
            })
            .collect();
        if !rest.is_empty() {
            let test = Dataset::new(t, rest.clone(), &name, Part::Test);
            let first = chunk.first_row;
            let (nominal, k, _) = held_out_errors(model, &kinematic, &test, calibration)
                .map_err(|e| in_file(e, first))?;
            let a = final_errors(&adopted, &test).map_err(|e| in_file(e, first))?;
            for (i, &r) in rest.iter().enumerate() {
                let key = t.pose_key(r);
                sums[0].add(key, &nominal[i]);
                sums[1].add(key, &k[i]);
                sums[2].add(key, &a[i]);
            }
            predicted += rest.len();
        }
        done += t.len();
        progress(&format!("predicting the rest of {name}: {done} rows"));
    }
    passes += 1;
    let [nominal, kinematic, adopted] = sums.map(HeldOutSum::finish);
    let gain = if kinematic.rms_m > 0.0 {
        1.0 - adopted.rms_m / kinematic.rms_m
    } else {
        0.0
    };
    Ok(StreamedDiagnosis {
        diagnosis,
        rows,
        sample_rows: rows - predicted,
        passes,
        rest: Some(RestOfStream {
            rows: predicted,
            model: adopted_name,
            nominal,
            kinematic,
            adopted,
            gain,
        }),
    })
}
