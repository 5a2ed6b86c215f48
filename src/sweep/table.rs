//! The sweep's Parquet file: one row per run ([`SweepRow`], columns documented in [`COLUMNS`]) and the
//! sweep description in the file's key-value metadata.
//!
//! Bytes depend only on the rows and the metadata: every writer property is set explicitly, nothing
//! records a time, a path, a host or a thread count, and rows are always written in run order. That is
//! what makes a merge of shards byte-identical to a single run.

use arrow_array::{
    Array, ArrayRef, BooleanArray, Float64Array, Int64Array, RecordBatch, StringArray, UInt64Array,
};
use arrow_schema::{DataType, Field, Schema};
use std::path::Path;
use std::sync::Arc;

/// Metadata key holding the sweep description (JSON, see `super::SweepSpec`); identical in every
/// shard of one sweep and in the merged file.
pub const META_SWEEP: &str = "robocal.sweep";
/// Metadata key holding the column documentation (JSON object: name → meaning with unit).
pub const META_COLUMNS: &str = "robocal.sweep.columns";
/// Metadata key present only in a partial file (a `--shard` or `--only-cell` run): which part it is.
pub const META_SUBSET: &str = "robocal.sweep.subset";

/// Rows per row group (a constant, so that the bytes do not depend on how rows arrived).
const ROW_GROUP_ROWS: usize = 65_536;

/// An Arrow column type of the sweep table.
trait ColumnType: Sized + Clone {
    fn data_type() -> DataType;
    fn array(values: Vec<Self>) -> ArrayRef;
    fn read(array: &dyn Array) -> Option<Vec<Self>>;
}

impl ColumnType for i64 {
    fn data_type() -> DataType {
        DataType::Int64
    }
    fn array(values: Vec<Self>) -> ArrayRef {
        Arc::new(Int64Array::from(values))
    }
    fn read(array: &dyn Array) -> Option<Vec<Self>> {
        let a = array.as_any().downcast_ref::<Int64Array>()?;
        (a.null_count() == 0).then(|| a.values().to_vec())
    }
}

impl ColumnType for u64 {
    fn data_type() -> DataType {
        DataType::UInt64
    }
    fn array(values: Vec<Self>) -> ArrayRef {
        Arc::new(UInt64Array::from(values))
    }
    fn read(array: &dyn Array) -> Option<Vec<Self>> {
        let a = array.as_any().downcast_ref::<UInt64Array>()?;
        (a.null_count() == 0).then(|| a.values().to_vec())
    }
}

impl ColumnType for f64 {
    fn data_type() -> DataType {
        DataType::Float64
    }
    fn array(values: Vec<Self>) -> ArrayRef {
        Arc::new(Float64Array::from(values))
    }
    fn read(array: &dyn Array) -> Option<Vec<Self>> {
        let a = array.as_any().downcast_ref::<Float64Array>()?;
        (a.null_count() == 0).then(|| a.values().to_vec())
    }
}

impl ColumnType for bool {
    fn data_type() -> DataType {
        DataType::Boolean
    }
    fn array(values: Vec<Self>) -> ArrayRef {
        Arc::new(BooleanArray::from(values))
    }
    fn read(array: &dyn Array) -> Option<Vec<Self>> {
        let a = array.as_any().downcast_ref::<BooleanArray>()?;
        (a.null_count() == 0).then(|| (0..a.len()).map(|i| a.value(i)).collect())
    }
}

impl ColumnType for String {
    fn data_type() -> DataType {
        DataType::Utf8
    }
    fn array(values: Vec<Self>) -> ArrayRef {
        Arc::new(StringArray::from(values))
    }
    fn read(array: &dyn Array) -> Option<Vec<Self>> {
        let a = array.as_any().downcast_ref::<StringArray>()?;
        (a.null_count() == 0).then(|| (0..a.len()).map(|i| a.value(i).to_string()).collect())
    }
}

/// Declares [`SweepRow`], [`COLUMNS`] and the conversions from one list of `name: type = "doc"`.
macro_rules! sweep_columns {
    ($( $field:ident : $ty:ty = $doc:literal ),* $(,)?) => {
        /// One run of a sweep: what was generated, how the calibration went, and its scores against
        /// the truth. Units are in the field names (`_m` metres); see [`COLUMNS`].
        #[derive(Clone, Debug, PartialEq)]
        pub struct SweepRow {
            $( #[doc = $doc] pub $field: $ty, )*
        }

        /// Column names and their meaning (with units), in file order.
        pub const COLUMNS: &[(&str, &str)] = &[ $( (stringify!($field), $doc) ),* ];

        fn arrays(rows: &[SweepRow]) -> Vec<ArrayRef> {
            vec![ $( <$ty as ColumnType>::array(rows.iter().map(|r| r.$field.to_owned()).collect()) ),* ]
        }

        fn fields() -> Vec<Field> {
            vec![ $( Field::new(stringify!($field), <$ty as ColumnType>::data_type(), false) ),* ]
        }

        fn rows_of(batch: &RecordBatch, file: &str) -> Result<Vec<SweepRow>, String> {
            $(
                let $field: Vec<$ty> = {
                    let name = stringify!($field);
                    let col = batch
                        .column_by_name(name)
                        .ok_or_else(|| format!("{file}: column '{name}' is missing: not a sweep file"))?;
                    <$ty as ColumnType>::read(col.as_ref()).ok_or_else(|| {
                        format!("{file}: column '{name}' has type {} or nulls, expected {} without nulls",
                            col.data_type(), <$ty as ColumnType>::data_type())
                    })?
                };
            )*
            Ok((0..batch.num_rows()).map(|i| SweepRow { $( $field: $field[i].to_owned(), )* }).collect())
        }
    };
}

sweep_columns! {
    run: i64 = "run index, 0-based: cell · reps + rep",
    cell: i64 = "cell index, 0-based: ((magnitude index · (number of payload sets) + payload-set index) · (number of noise levels) + noise index) · (number of pose counts) + pose-count index (one payload set, index 0, without --payloads)",
    rep: i64 = "repetition within the cell, 0-based",
    noise_scale: f64 = "tracker noise multiplier (the value of --noise, as in `robocal generate --noise`)",
    poses: i64 = "poses generated for the run (as `robocal generate --poses`)",
    magnitude: f64 = "factor on the injected effects (the value of --magnitude; 1 = the scenario as written, 0 = absent)",
    payloads: String = "the run's payload set (--payloads): its masses in kg, `/`-separated (`0/3.5/7`: each pose carries one of them, drawn; `7`: every pose); empty for the scenario's own payloads",
    seed: u64 = "seed of the run's dataset and split (`robocal generate --seed`, `robocal calibrate --seed`)",
    train_poses: i64 = "poses the calibration used",
    test_poses: i64 = "poses held out for scoring",
    sigma_rms_m: f64 = "RMS over the rows of the tracker's per-axis standard deviation, the `sigma` column (m); 0 without noise",
    injected_rms_m: f64 = "RMS over the rows of the displacement of the real target from the nominal one by all injected effects (m)",
    converged: bool = "the fit converged",
    iterations: i64 = "solver iterations of the fit",
    chi2_per_dof: f64 = "χ²/dof of the fit (1 when the noise model is right and the model explains the data)",
    train_rms_m: f64 = "RMS of |predicted − measured| on the training rows after calibration (m)",
    test_rms_measured_m: f64 = "RMS of |predicted − measured| on the held-out rows (m): the test RMS `robocal calibrate` reports",
    test_error_rms_m: f64 = "RMS of |predicted − true| on the held-out rows, against the noise-free true target (m)",
    test_error_max_m: f64 = "largest |predicted − true| on the held-out rows (m)",
    test_error_predicted_m: f64 = "what the covariance predicts for test_error_rms_m: √(mean over held-out rows of trace(J C Jᵀ)) (m)",
    test_error_nominal_rms_m: f64 = "RMS of |predicted − true| on the held-out rows for the nominal robot with only base and target fitted (m)",
    rank: i64 = "identifiable parameter combinations of the calibration (31 for the kinematic iiwa 7 from positions: 4R + 2P + 3; extension parameters add theirs)",
    param_combinations: i64 = "identifiable parameter combinations scored (rank of J C Jᵀ at the training poses; equals rank unless the prediction Jacobian is degenerate)",
    param_z2_mean: f64 = "mean of z_k² over the identifiable combinations, z_k = their error in units of the predicted σ (1 expected)",
    param_z_abs_max: f64 = "largest |z_k| (about 3 expected for r ≈ 31)",
    param_beyond_3sigma: i64 = "identifiable combinations with |z_k| > 3 (0.27 % of r expected)",
    condition_number: f64 = "condition number σ₁/σ_r of the scaled, noise-weighted Jacobian of the training poses",
    sigma_min: f64 = "smallest identifiable singular value σ_r of that Jacobian (dimensionless: scaled by the expected parameter magnitudes and the noise)",
    log_det_information: f64 = "log det of the scaled information matrix in the identifiable subspace (the D-optimal criterion)",
    learned: bool = "the fitted model has a learned residual correction (held-out errors include it; the predicted error and the combinations are the physical model's)",
    params_joint_compliance: i64 = "joint_compliance parameters in the fitted model (0: not in it)",
    param_z2_mean_joint_compliance: f64 = "mean z² of the joint_compliance parameters with a z (FILE.params.parquet; 1 expected; NaN without any)",
    params_gear_backlash: i64 = "gear_backlash parameters in the fitted model (0: not in it)",
    param_z2_mean_gear_backlash: f64 = "mean z² of the gear_backlash parameters with a z (1 expected; NaN without any)",
    params_thermal_drift: i64 = "thermal_drift parameters in the fitted model (0: not in it)",
    param_z2_mean_thermal_drift: f64 = "mean z² of the thermal_drift parameters with a z (NaN without any: an injected thermal drift is not mapped)",
    params_transmission_error: i64 = "transmission_error parameters in the fitted model (0: not in it)",
    param_z2_mean_transmission_error: f64 = "mean z² of the transmission_error parameters with a z (1 expected; NaN without any)",
    params_link_deflection: i64 = "link_deflection parameters in the fitted model (0: not in it)",
    param_z2_mean_link_deflection: f64 = "mean z² of the link_deflection parameters with a z (1 expected; NaN without any)",
    hidden: String = "--score diagnose: the causes the run injected, at their joints, as a model name (`kinematic+gear_backlash@2,4`; `kinematic`: none); empty without --score diagnose",
    named: String = "--score diagnose: diagnose's findings on the run's data, each cause at the joints it names, all listed (`kinematic+link_deflection@2,4`; a cause without `@`: named with no joint significant on its own); empty without --score diagnose",
    detected: bool = "--score diagnose: diagnose named every hidden cause and none at a joint where it is not hidden (hidden joints may be left out); false without --score diagnose",
    false_alarm: bool = "--score diagnose: diagnose named a cause that is not hidden, or one at a joint where it is not hidden; false without --score diagnose",
}

/// The `params_<cause>` and `param_z2_mean_<cause>` fields of a row, in [`calib::model::extensions::Cause::ALL`]
/// order.
impl SweepRow {
    /// `(params, z² mean)` of each cause, in `Cause::ALL` order.
    pub fn causes(&self) -> [(i64, f64); 5] {
        [
            (
                self.params_joint_compliance,
                self.param_z2_mean_joint_compliance,
            ),
            (self.params_gear_backlash, self.param_z2_mean_gear_backlash),
            (self.params_thermal_drift, self.param_z2_mean_thermal_drift),
            (
                self.params_transmission_error,
                self.param_z2_mean_transmission_error,
            ),
            (
                self.params_link_deflection,
                self.param_z2_mean_link_deflection,
            ),
        ]
    }

    /// Sets the cause fields from `scores` (`Cause::ALL` order).
    pub fn set_causes(&mut self, scores: &[(i64, f64)]) {
        let get = |k: usize| scores.get(k).copied().unwrap_or((0, f64::NAN));
        (
            self.params_joint_compliance,
            self.param_z2_mean_joint_compliance,
        ) = get(0);
        (self.params_gear_backlash, self.param_z2_mean_gear_backlash) = get(1);
        (self.params_thermal_drift, self.param_z2_mean_thermal_drift) = get(2);
        (
            self.params_transmission_error,
            self.param_z2_mean_transmission_error,
        ) = get(3);
        (
            self.params_link_deflection,
            self.param_z2_mean_link_deflection,
        ) = get(4);
    }
}

/// Deterministic Parquet bytes of `rows` (in the order given) with the key-value `metadata`.
pub fn parquet_bytes(rows: &[SweepRow], metadata: &[(String, String)]) -> Result<Vec<u8>, String> {
    use parquet::file::metadata::KeyValue;
    let kv: Vec<KeyValue> = metadata
        .iter()
        .map(|(k, v)| KeyValue::new(k.clone(), v.clone()))
        .collect();
    let props = sim::io::deterministic_writer_properties(ROW_GROUP_ROWS)
        .set_key_value_metadata(Some(kv))
        .build();
    let schema = Arc::new(Schema::new(fields()));
    let batch = RecordBatch::try_new(schema, arrays(rows))
        .map_err(|e| format!("cannot build the sweep table: {e}"))?;
    sim::io::parquet_bytes(&batch, props, ROW_GROUP_ROWS)
        .map_err(|e| format!("cannot write Parquet: {e}"))
}

/// A sweep file read back: its rows (file order) and key-value metadata.
#[derive(Clone, Debug)]
pub struct SweepFile {
    /// Rows in file order.
    pub rows: Vec<SweepRow>,
    /// Key-value metadata.
    pub metadata: Vec<(String, String)>,
}

impl SweepFile {
    /// The value of metadata key `key`.
    pub fn meta(&self, key: &str) -> Option<&str> {
        self.metadata
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }
}

/// Reads a sweep Parquet file; errors are one line naming the file.
pub fn read(path: &Path) -> Result<SweepFile, String> {
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| format!("{file}: cannot open: {e}"))?;
    let b = ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| format!("{file}: not a Parquet file: {e}"))?;
    let metadata = b
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .map(|kv| {
            kv.iter()
                .filter(|k| k.key != "ARROW:schema")
                .map(|k| (k.key.clone(), k.value.clone().unwrap_or_default()))
                .collect()
        })
        .unwrap_or_default();
    let reader = b.build().map_err(|e| format!("{file}: cannot read: {e}"))?;
    let mut rows = Vec::new();
    for batch in reader {
        let batch = batch.map_err(|e| format!("{file}: cannot read: {e}"))?;
        rows.extend(rows_of(&batch, &file)?);
    }
    Ok(SweepFile { rows, metadata })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(run: i64) -> SweepRow {
        SweepRow {
            run,
            cell: run / 3,
            rep: run % 3,
            noise_scale: 0.5,
            poses: 40,
            payloads: String::new(),
            magnitude: 1.0,
            seed: u64::MAX - run as u64,
            train_poses: 28,
            test_poses: 12,
            sigma_rms_m: 1.1e-5,
            injected_rms_m: 3e-4,
            converged: run % 2 == 0,
            iterations: 4,
            chi2_per_dof: 1.01,
            train_rms_m: 1.6e-5,
            test_rms_measured_m: 2.1e-5,
            test_error_rms_m: 7.2e-6 + run as f64 * 1e-9,
            test_error_max_m: 1.3e-5,
            test_error_predicted_m: 7e-6,
            test_error_nominal_rms_m: 8e-4,
            rank: 31,
            param_combinations: 31,
            param_z2_mean: 0.97,
            param_z_abs_max: 2.4,
            param_beyond_3sigma: 0,
            condition_number: 1.2e3,
            sigma_min: 4.5,
            log_det_information: 201.5,
            learned: false,
            params_joint_compliance: 7,
            param_z2_mean_joint_compliance: 0.9,
            params_gear_backlash: 0,
            param_z2_mean_gear_backlash: 1.1,
            params_thermal_drift: 0,
            param_z2_mean_thermal_drift: 1.2000000000000002,
            params_transmission_error: 0,
            param_z2_mean_transmission_error: 1.3,
            params_link_deflection: 0,
            param_z2_mean_link_deflection: 1.4000000000000001,
            hidden: "kinematic+gear_backlash@2,4".into(),
            named: if run % 2 == 0 {
                "kinematic".into()
            } else {
                String::new()
            },
            detected: run % 3 == 0,
            false_alarm: false,
        }
    }

    #[test]
    fn rows_and_metadata_round_trip_exactly_and_bytes_are_reproducible() {
        let rows: Vec<SweepRow> = (0..7).map(row).collect();
        let meta = vec![(META_SWEEP.to_string(), "{\"a\":1}".to_string())];
        let bytes = parquet_bytes(&rows, &meta).unwrap();
        assert_eq!(bytes, parquet_bytes(&rows, &meta).unwrap());
        let dir = std::env::temp_dir().join(format!("robocal_sweep_table_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.parquet");
        std::fs::write(&p, &bytes).unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.rows, rows);
        assert_eq!(back.meta(META_SWEEP), Some("{\"a\":1}"));
        assert_eq!(back.meta(META_SUBSET), None);
        // Written again from what was read: the same bytes.
        assert_eq!(parquet_bytes(&back.rows, &back.metadata).unwrap(), bytes);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The cause columns follow calib's registry: a new cause needs its two columns.
    #[test]
    fn every_cause_has_its_columns_in_registry_order() {
        use calib::model::extensions::Cause;
        assert_eq!(Cause::ALL.len(), row(0).causes().len());
        for (k, c) in Cause::ALL.iter().enumerate() {
            let names: Vec<&str> = COLUMNS.iter().map(|(n, _)| *n).collect();
            let at = names
                .iter()
                .position(|n| *n == format!("params_{}", c.name()))
                .unwrap_or_else(|| panic!("no column params_{c}"));
            assert_eq!(names[at + 1], format!("param_z2_mean_{}", c.name()));
            let mut r = row(0);
            let mut scores = vec![(0, f64::NAN); Cause::ALL.len()];
            scores[k] = (3, 0.5);
            r.set_causes(&scores);
            assert_eq!(r.causes()[k], (3, 0.5));
        }
    }

    #[test]
    fn every_column_is_documented_in_docs_sweep_md() {
        let doc = include_str!("../../docs/sweep.md");
        for (name, _) in COLUMNS {
            assert!(
                doc.contains(&format!("| `{name}` |")),
                "docs/sweep.md misses column {name}"
            );
        }
    }

    #[test]
    fn a_file_that_is_not_a_sweep_is_refused_by_name() {
        let dir = std::env::temp_dir().join(format!("robocal_sweep_bad_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("junk.parquet");
        std::fs::write(&p, b"not parquet").unwrap();
        let e = read(&p).unwrap_err();
        assert!(e.starts_with(&p.display().to_string()), "{e}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
