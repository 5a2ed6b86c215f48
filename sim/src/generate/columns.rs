//! The columns of the output files: the measurement table of a simulation (the optional columns of
//! `measurements.parquet`), the `truth.parquet` schema and its record batches (see [`super`]).

use super::TRUTH_PARQUET_FILE;
use super::simulate::{RowTruth, Simulation};
use crate::campaign::Plan;
use crate::effects::EffectId;
use crate::error::{Result, SimError};
use crate::measurement_table::{BranchColumns, MeasurementTable, OptionalColumns};
use crate::tracker::Tracker;
use arrow_array::{ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch};
use arrow_schema::{DataType, Field, Schema};
use std::path::PathBuf;
use std::sync::Arc;

/// Names of the `truth.parquet` columns for `nq` joints (see the module docs).
pub fn truth_column_names(nq: usize, six_dof: bool) -> Vec<String> {
    let mut v: Vec<String> = vec!["pose".into(), "repeat".into()];
    let effects = EffectId::ALL.iter().map(|id| id.key());
    for p in ["p_tracker", "p_base", "p_nominal_base"]
        .into_iter()
        .chain(effects)
    {
        for a in ["x", "y", "z"] {
            v.push(format!("{p}_{a}"));
        }
    }
    v.extend((1..=nq).map(|j| format!("q_link{j}")));
    v.extend((1..=nq).map(|j| format!("q_link_first_order{j}")));
    v.extend(
        [
            "noise_x",
            "noise_y",
            "noise_z",
            "outlier",
            "sigma_radial",
            "sigma_transverse",
        ]
        .map(String::from),
    );
    v.push("compliance_iterations".into());
    if six_dof {
        v.extend(
            [
                "qw_true",
                "qx_true",
                "qy_true",
                "qz_true",
                "rot_noise_x",
                "rot_noise_y",
                "rot_noise_z",
            ]
            .map(String::from),
        );
    }
    v
}

/// The `truth.parquet` record batch.
pub(super) fn truth_batch(plan: &Plan, sim: &Simulation, six_dof: bool) -> Result<RecordBatch> {
    let nq = plan.nq;
    let rows = &sim.rows;
    let f = |v: Vec<f64>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let col3 = |g: &dyn Fn(&RowTruth) -> [f64; 3]| -> [ArrayRef; 3] {
        std::array::from_fn(|k| f(rows.iter().map(|r| g(r)[k]).collect()))
    };
    let mut arrays: Vec<ArrayRef> = vec![
        Arc::new(Int64Array::from(plan.pose.clone())),
        Arc::new(Int64Array::from(
            (0..plan.len())
                .map(|r| plan.repeat_of(r) as i64)
                .collect::<Vec<_>>(),
        )),
    ];
    arrays.extend(col3(&|r| r.reading.p_true));
    arrays.extend(col3(&|r| r.p_base));
    arrays.extend(col3(&|r| {
        let t = r.contribution.total();
        std::array::from_fn(|k| r.p_base[k] - t[k])
    }));
    for id in EffectId::ALL {
        arrays.extend(col3(&|r| r.contribution.get(*id)));
    }
    for j in 0..nq {
        arrays.push(f((0..plan.len()).map(|r| sim.q_link[r * nq + j]).collect()));
    }
    for j in 0..nq {
        arrays.push(f((0..plan.len())
            .map(|r| sim.q_link_first_order[r * nq + j])
            .collect()));
    }
    arrays.extend(col3(&|r| r.reading.noise));
    arrays.push(Arc::new(BooleanArray::from(
        rows.iter().map(|r| r.reading.outlier).collect::<Vec<_>>(),
    )));
    arrays.push(f(rows.iter().map(|r| r.reading.sigma_radial_m).collect()));
    arrays.push(f(rows
        .iter()
        .map(|r| r.reading.sigma_transverse_m)
        .collect()));
    arrays.push(Arc::new(Int64Array::from(
        rows.iter()
            .map(|r| r.compliance_iterations as i64)
            .collect::<Vec<_>>(),
    )));
    if six_dof {
        for k in 0..4 {
            arrays.push(f(rows
                .iter()
                .map(|r| r.reading.orientation_true[k])
                .collect()));
        }
        arrays.extend(col3(&|r| r.reading.orientation_noise));
    }
    RecordBatch::try_new(truth_schema(nq, six_dof), arrays).map_err(|e| SimError::Io {
        path: PathBuf::from(TRUTH_PARQUET_FILE),
        source: std::io::Error::other(e.to_string()),
    })
}

/// The Arrow schema of `truth.parquet`: `pose`, `repeat` and `compliance_iterations` Int64, `outlier`
/// Boolean, every other column Float64; none nullable.
pub(super) fn truth_schema(nq: usize, six_dof: bool) -> Arc<Schema> {
    let fields: Vec<Field> = truth_column_names(nq, six_dof)
        .into_iter()
        .map(|name| {
            let dt = match name.as_str() {
                "pose" | "repeat" | "compliance_iterations" => DataType::Int64,
                "outlier" => DataType::Boolean,
                _ => DataType::Float64,
            };
            Field::new(name, dt, false)
        })
        .collect();
    Arc::new(Schema::new(fields))
}

/// The optional columns of the measurement table (see the module docs).
pub(super) fn measurement_columns(has_dir: bool, tracker: &Tracker) -> OptionalColumns {
    OptionalColumns {
        orientation: tracker.six_dof(),
        t: true,
        temp: true,
        dir: has_dir,
        payload: true,
        sigma: tracker.noise_scale() > 0.0,
        campaign: false,
    }
}

/// The measurement table of a simulation: contract columns only (see the module docs).
pub fn measurement_table(plan: &Plan, sim: &Simulation, tracker: &Tracker) -> MeasurementTable {
    let cols = measurement_columns(plan.dir.is_some(), tracker);
    let table = MeasurementTable {
        n_joints: plan.nq,
        pose: plan.pose.clone(),
        q: plan.q.clone(),
        position: sim.rows.iter().map(|r| r.reading.p_measured).collect(),
        orientation: cols.orientation.then(|| {
            sim.rows
                .iter()
                .map(|r| r.reading.orientation_measured)
                .collect()
        }),
        t: Some(plan.t_s.clone()),
        temp: Some(plan.temp_c.clone()),
        dir: plan.dir.clone(),
        payload: Some(plan.payload_kg.clone()),
        sigma: cols
            .sigma
            .then(|| sim.rows.iter().map(|r| r.reading.sigma_m).collect()),
        campaign: None,
        branch: plan.branch.clone().map(|values| BranchColumns {
            names: plan.branch_names.clone(),
            values,
        }),
    };
    match &plan.drives {
        None => table,
        Some(drives) => crate::measurement_table::drive_columns(table, drives),
    }
}
