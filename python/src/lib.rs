//! `robocal._robocal`: the native module of the Python package `robocal` (`python/robocal/`). It is a
//! thin layer over the crates the command line uses: robots and kinematics from `sim`, calibration and
//! diagnosis from `calib`, and the command line's own glue from the `robocal` library (`src/cli`):
//! reading a table against a robot, flag values to calib's options ([`robocal::cli::flags`]), the JSON
//! documents of `calibrate`, `diagnose` and `generate`. Nothing is computed here that the command line
//! computes otherwise, so both give the same numbers and the same messages.
//!
//! * Errors: [`CliError::Input`] (the command line's exit 2) raises `robocal.BadInput`,
//!   [`CliError::Runtime`] (exit 1) `robocal.RuntimeFailure`, with the command line's one-line message;
//!   a panic (a bug) raises `RuntimeFailure` instead of aborting the interpreter.
//! * Long work ([`work`]) runs with the GIL released, under a [`calib::cancel`] check that takes the
//!   GIL back for a moment to let Python handle signals: Ctrl-C raises `KeyboardInterrupt` at the next
//!   checkpoint (a Levenberg–Marquardt iteration, a candidate of diagnose).
//! * Tables come in as numpy arrays read in place ([`Table::from_columns`]: each array is borrowed as a
//!   slice and copied once, into the table's layout) and go out as numpy arrays that own the vectors
//!   the Rust side built (no further copy).

use calib::model::predict::Predictor;
use numpy::{
    AllowTypeChange, PyArray1, PyArray2, PyArrayDyn, PyArrayLikeDyn, PyArrayMethods,
    PyReadonlyArray1, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyType;
use robocal::cli::{
    calibrate as cal_cli, compensate as comp_cli, diagnose as diag_cli, flags, generate as gen_cli,
    plan_poses as plan_cli, predict, register as reg_cli,
};
use robocal::error::CliError;
use sim::Frame;
use sim::measurement_table::{self, Column, ColumnValues, MeasurementTable};
use std::panic::AssertUnwindSafe;
use std::path::Path;
use std::sync::{Arc, Mutex};

/// The Python exception for a [`CliError`]: `robocal.BadInput` or `robocal.RuntimeFailure` (defined
/// in `robocal/_errors.py`), with the message on one line as the command line prints it.
fn raise(py: Python<'_>, e: CliError) -> PyErr {
    let (class, message) = match &e {
        CliError::Input(m) => ("BadInput", m),
        CliError::Runtime(m) => ("RuntimeFailure", m),
    };
    let message = sim::error::one_line(message);
    match py
        .import("robocal._errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| Ok(c.cast_into::<PyType>()?))
    {
        Ok(ty) => PyErr::from_type(ty, message),
        Err(err) => err,
    }
}

/// Runs `f` (long work) with the GIL released and Ctrl-C able to stop it: a [`calib::cancel`] check
/// takes the GIL at each checkpoint to run Python's signal handlers, and the first exception they
/// raise (`KeyboardInterrupt`) is raised here once the work has stopped. A panic becomes
/// `RuntimeFailure` rather than aborting the interpreter.
fn work<T: Send>(py: Python<'_>, f: impl FnOnce() -> Result<T, CliError> + Send) -> PyResult<T> {
    let interrupt: Arc<Mutex<Option<PyErr>>> = Arc::default();
    let seen = interrupt.clone();
    let out = py.detach(move || {
        let check = move || {
            Python::attach(|py| match py.check_signals() {
                Ok(()) => false,
                Err(e) => {
                    *seen.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                    true
                }
            })
        };
        std::panic::catch_unwind(AssertUnwindSafe(|| calib::cancel::with_check(check, f)))
    });
    if let Some(e) = interrupt.lock().unwrap_or_else(|p| p.into_inner()).take() {
        return Err(e);
    }
    match out {
        Ok(r) => r.map_err(|e| raise(py, e)),
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            Err(raise(
                py,
                CliError::Runtime(format!(
                    "internal error (a bug in robocal, please report it): {what}"
                )),
            ))
        }
    }
}

/// Short work that needs no GIL release: its error as the Python exception.
fn quick<T>(py: Python<'_>, r: Result<T, CliError>) -> PyResult<T> {
    r.map_err(|e| raise(py, e))
}

/// `warnings.warn(message, robocal.DataWarning)` for each message, attributed to the caller's line:
/// `depth` 1 for a method the user calls directly, 2 for one called through `robocal/__init__.py`.
fn warn(py: Python<'_>, messages: &[String], depth: usize) -> PyResult<()> {
    if messages.is_empty() {
        return Ok(());
    }
    let category = py.import("robocal._errors")?.getattr("DataWarning")?;
    let warnings = py.import("warnings")?;
    for m in messages {
        warnings.call_method1("warn", (m.as_str(), &category, depth))?;
    }
    Ok(())
}

/// A robot: the chain from a URDF (a built-in one or a file), with its URDF text.
#[pyclass(frozen, module = "robocal._robocal")]
struct Robot {
    robot: calib::model::robot::Robot,
}

#[pymethods]
impl Robot {
    /// Loads a robot: a URDF file path, or a built-in name (`iiwa7`, `ur5`, `ur10`, `wam`). The chain
    /// runs from `base_link` (default: the URDF's root link) to `tip_link` (default: its single leaf).
    /// `couplings`: a TOML file of coupled joints declared beside the URDF (as `--couplings`).
    #[staticmethod]
    #[pyo3(signature = (robot = "iiwa7", base_link = None, tip_link = None, couplings = None))]
    fn load(
        py: Python<'_>,
        robot: &str,
        base_link: Option<String>,
        tip_link: Option<String>,
        couplings: Option<String>,
    ) -> PyResult<Self> {
        let args = robocal::cli::robot_arg::RobotArgs {
            robot: robot.to_string(),
            base_link,
            tip_link,
            couplings: couplings.map(std::path::PathBuf::from),
        };
        let robot = quick(py, args.load_robot())?;
        Ok(Robot { robot })
    }

    /// The robot's name.
    #[getter]
    fn name(&self) -> &str {
        self.robot.model.name()
    }

    /// Names of the joints of the chain, base to tip.
    #[getter]
    fn joint_names(&self) -> Vec<String> {
        self.robot
            .model
            .joints()
            .iter()
            .map(|j| j.name.clone())
            .collect()
    }

    /// Number of joints (degrees of freedom) of the chain.
    #[getter]
    fn dof(&self) -> usize {
        self.robot.model.nq()
    }

    /// The chain's base link.
    #[getter]
    fn base_link(&self) -> &str {
        self.robot.model.base_link()
    }

    /// The chain's tip (flange) link.
    #[getter]
    fn tip_link(&self) -> &str {
        self.robot.model.tip_link()
    }

    /// Where the robot came from: a file path or `built-in robot 'NAME'`.
    #[getter]
    fn source(&self) -> &str {
        &self.robot.source
    }

    /// The URDF text.
    #[getter]
    fn urdf(&self) -> &str {
        &self.robot.urdf
    }

    /// Lower and upper joint limits (rad or m) per joint; NaN where a joint has none.
    #[getter]
    fn limits<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let rows: Vec<Vec<f64>> = self
            .robot
            .model
            .joints()
            .iter()
            .map(|j| match j.limits {
                Some(l) => vec![l.lower, l.upper],
                None => vec![f64::NAN, f64::NAN],
            })
            .collect();
        PyArray2::from_vec2(py, &rows).expect("two values per joint")
    }

    /// `T_base_flange` (4×4 homogeneous, m) at `q` (rad, or m for prismatic joints), or a stack of
    /// them (N×4×4) for N configurations (N×dof).
    fn fk<'py>(
        &self,
        py: Python<'py>,
        q: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
    ) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let model = &self.robot.model;
        let (rows, single) = self.configurations(py, &q)?;
        let n = rows.len() / model.nq().max(1);
        let mut out = vec![0.0; n * 16];
        let mut data = sim::Data::new(model);
        for (k, q) in rows.chunks(model.nq()).enumerate() {
            let t = sim::flange_pose(model, &mut data, q).to_homogeneous();
            for r in 0..4 {
                for c in 0..4 {
                    out[k * 16 + r * 4 + c] = t[(r, c)];
                }
            }
        }
        let shape: Vec<usize> = if single { vec![4, 4] } else { vec![n, 4, 4] };
        PyArray1::from_vec(py, out).reshape(shape)
    }

    /// The flange Jacobian (6×dof) at `q` (rad or m), rows `[ω; v]`: angular velocity first, then
    /// linear velocity (rad/s and m/s per unit q̇). `frame`: `"spatial"` (default; the spatial twist
    /// in the base frame: ω and the velocity of the point at the base origin moving with the flange),
    /// `"body"` (the body twist in the flange frame) or `"local_world_aligned"` (ω and the velocity of
    /// the flange origin, both in base-frame axes). Pinocchio orders rows `[v; ω]`: its `WORLD`
    /// Jacobian is `J[[3, 4, 5, 0, 1, 2]]` of `"spatial"`, `LOCAL` that of `"body"`,
    /// `LOCAL_WORLD_ALIGNED` that of `"local_world_aligned"`.
    #[pyo3(signature = (q, frame = "spatial"))]
    fn jacobian<'py>(
        &self,
        py: Python<'py>,
        q: PyArrayLikeDyn<'py, f64, AllowTypeChange>,
        frame: &str,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let frame = match frame {
            "spatial" => Frame::Spatial,
            "body" => Frame::Body,
            "local_world_aligned" => Frame::LocalWorldAligned,
            other => {
                return Err(raise(
                    py,
                    CliError::Input(format!(
                        "frame '{other}': not one of spatial, body, local_world_aligned"
                    )),
                ));
            }
        };
        let model = &self.robot.model;
        let (q, single) = self.configurations(py, &q)?;
        if !single {
            return Err(raise(
                py,
                CliError::Input("q: one configuration (a vector of dof values) is expected".into()),
            ));
        }
        let mut data = sim::Data::new(model);
        sim::forward_kinematics(model, &mut data, &q);
        let mut j = nalgebra::Matrix6xX::zeros(model.nq());
        sim::kinematics::frame_jacobian(model, &mut data, frame, &mut j);
        let rows: Vec<Vec<f64>> = (0..6)
            .map(|r| (0..model.nq()).map(|c| j[(r, c)]).collect())
            .collect();
        Ok(PyArray2::from_vec2(py, &rows).expect("6 rows of dof values"))
    }

    fn __repr__(&self) -> String {
        format!(
            "Robot('{}', dof={}, {} -> {})",
            self.robot.model.name(),
            self.robot.model.nq(),
            self.robot.model.base_link(),
            self.robot.model.tip_link()
        )
    }
}

impl Robot {
    /// The joint values of `q` (one configuration, or N×dof row by row) checked against the chain, and
    /// whether it was one; values beyond the joint limits give a `DataWarning` each (as `robocal fk`).
    fn configurations(
        &self,
        py: Python<'_>,
        q: &PyArrayLikeDyn<'_, f64, AllowTypeChange>,
    ) -> PyResult<(Vec<f64>, bool)> {
        let model = &self.robot.model;
        let single = q.ndim() <= 1;
        let bad = |m: String| raise(py, CliError::Input(m));
        if q.ndim() > 2 || (q.ndim() == 2 && q.shape()[1] != model.nq()) {
            return Err(bad(format!(
                "q: shape {:?}: expected ({},) or (N, {}) for robot '{}'",
                q.shape(),
                model.nq(),
                model.nq(),
                model.name()
            )));
        }
        let values: Vec<f64> = q.as_array().iter().copied().collect();
        let mut warnings = Vec::new();
        for row in values.chunks(model.nq().max(1)) {
            model
                .check_q(row)
                .map_err(|e| bad(format!("q: {e} (robot '{}')", model.name())))?;
            for (i, (j, v)) in model.joints().iter().zip(row).enumerate() {
                if let Some(l) = j.limits
                    && (*v < l.lower || *v > l.upper)
                {
                    warnings.push(format!(
                        "q{} = {v} is outside the limits [{}, {}] of joint '{}'",
                        i + 1,
                        l.lower,
                        l.upper,
                        j.name
                    ));
                }
            }
        }
        if values.is_empty() {
            return Err(bad(format!(
                "q: no joint values (robot '{}' has {} joints)",
                model.name(),
                model.nq()
            )));
        }
        warnings.truncate(20);
        warn(py, &warnings, 1)?;
        Ok((values, single))
    }
}

/// A measurement table (the contract of `shared/spec/measurements.md`) held by the Rust side.
#[pyclass(frozen, module = "robocal._robocal")]
struct Table {
    table: MeasurementTable,
    source: String,
}

/// One column handed over from Python, borrowed for the conversion.
enum Held<'py> {
    F64(PyReadonlyArray1<'py, f64>),
    F32(PyReadonlyArray1<'py, f32>),
    I64(PyReadonlyArray1<'py, i64>),
    I32(PyReadonlyArray1<'py, i32>),
    I16(PyReadonlyArray1<'py, i16>),
    I8(PyReadonlyArray1<'py, i8>),
    U64(PyReadonlyArray1<'py, u64>),
    U32(PyReadonlyArray1<'py, u32>),
    U16(PyReadonlyArray1<'py, u16>),
    U8(PyReadonlyArray1<'py, u8>),
    Other(String),
}

impl<'py> Held<'py> {
    /// A 1-D numpy array of a numeric type, or a text naming another type.
    fn of(value: &Bound<'py, PyAny>) -> PyResult<Self> {
        macro_rules! try_types {
            ($($t:ty => $v:ident),*) => {
                $(if let Ok(a) = value.cast::<PyArray1<$t>>() {
                    return Ok(Held::$v(a.readonly()));
                })*
            };
        }
        try_types!(f64 => F64, f32 => F32, i64 => I64, i32 => I32, i16 => I16, i8 => I8,
                   u64 => U64, u32 => U32, u16 => U16, u8 => U8);
        if let Ok(s) = value.extract::<String>() {
            return Ok(Held::Other(s));
        }
        Err(PyTypeError::new_err(
            "a column must be a 1-D numpy array of a numeric type, or the name of its type",
        ))
    }

    /// The values as a borrowed slice (the array must be contiguous).
    fn values(&self) -> PyResult<ColumnValues<'_>> {
        let slice_err = |_| {
            PyTypeError::new_err("a column's numpy array must be contiguous (np.ascontiguousarray)")
        };
        Ok(match self {
            Held::F64(a) => ColumnValues::F64(a.as_slice().map_err(slice_err)?),
            Held::F32(a) => ColumnValues::F32(a.as_slice().map_err(slice_err)?),
            Held::I64(a) => ColumnValues::I64(a.as_slice().map_err(slice_err)?),
            Held::I32(a) => ColumnValues::I32(a.as_slice().map_err(slice_err)?),
            Held::I16(a) => ColumnValues::I16(a.as_slice().map_err(slice_err)?),
            Held::I8(a) => ColumnValues::I8(a.as_slice().map_err(slice_err)?),
            Held::U64(a) => ColumnValues::U64(a.as_slice().map_err(slice_err)?),
            Held::U32(a) => ColumnValues::U32(a.as_slice().map_err(slice_err)?),
            Held::U16(a) => ColumnValues::U16(a.as_slice().map_err(slice_err)?),
            Held::U8(a) => ColumnValues::U8(a.as_slice().map_err(slice_err)?),
            Held::Other(t) => ColumnValues::Other(t),
        })
    }
}

#[pymethods]
impl Table {
    /// Reads a measurement table file (`.csv` or `.parquet`) as `robocal calibrate --data` does; with
    /// `configurations`, `x, y, z` may be absent (as `robocal predict --data`).
    #[staticmethod]
    #[pyo3(signature = (path, configurations = false))]
    fn read(py: Python<'_>, path: &str, configurations: bool) -> PyResult<Self> {
        let table = work(py, || {
            let p = Path::new(path);
            Ok(if configurations {
                measurement_table::read_configurations(p)?
            } else {
                measurement_table::read(p)?
            })
        })?;
        Ok(Table {
            table,
            source: path.to_string(),
        })
    }

    /// A table from columns `(name, values, first_null)`: `values` a contiguous 1-D numpy array of a
    /// numeric type (read in place) or a text naming another type (an error unless the column is
    /// ignored), `first_null` the index of the first missing value or None. `source` names the table
    /// in errors, which are those of a file with these columns.
    #[staticmethod]
    #[pyo3(signature = (columns, source, configurations = false))]
    fn from_columns(
        py: Python<'_>,
        columns: Vec<(String, Bound<'_, PyAny>, Option<usize>)>,
        source: &str,
        configurations: bool,
    ) -> PyResult<Self> {
        let held: Vec<Held<'_>> = columns
            .iter()
            .map(|(_, v, _)| Held::of(v))
            .collect::<PyResult<_>>()?;
        let cols: Vec<Column<'_>> = columns
            .iter()
            .zip(&held)
            .map(|((name, _, first_null), h)| {
                Ok(Column {
                    name,
                    values: h.values()?,
                    first_null: *first_null,
                })
            })
            .collect::<PyResult<_>>()?;
        let table = quick(
            py,
            if configurations {
                measurement_table::configurations_from_columns(&cols, source)
            } else {
                measurement_table::from_columns(&cols, source)
            }
            .map_err(CliError::from),
        )?;
        Ok(Table {
            table,
            source: source.to_string(),
        })
    }

    /// The columns in file order, `(name, numpy array)`: `pose` int64, `dir*` int8, the rest float64.
    fn columns<'py>(&self, py: Python<'py>) -> Vec<(String, Bound<'py, PyAny>)> {
        let t = &self.table;
        let nq = t.n_joints;
        let n = t.len();
        let f = |v: Vec<f64>| PyArray1::from_vec(py, v).into_any();
        let mut out: Vec<(String, Bound<'py, PyAny>)> = vec![(
            "pose".into(),
            PyArray1::from_vec(py, t.pose.clone()).into_any(),
        )];
        for j in 0..nq {
            out.push((
                format!("q{}", j + 1),
                f((0..n).map(|r| t.q[r * nq + j]).collect()),
            ));
        }
        if let Some(b) = &t.branch {
            let nb = b.names.len();
            for (k, name) in b.names.iter().enumerate() {
                out.push((
                    format!("q_{name}"),
                    f((0..n).map(|r| b.values[r * nb + k]).collect()),
                ));
            }
        }
        target_columns(py, &t.position, t.orientation.as_deref(), &mut out);
        for (name, col) in [("t", &t.t), ("temp", &t.temp)] {
            if let Some(v) = col {
                out.push((name.into(), f(v.clone())));
            }
        }
        if let Some(d) = &t.dir {
            for j in 0..nq {
                let v: Vec<i8> = (0..n).map(|r| d[r * nq + j]).collect();
                out.push((
                    format!("dir{}", j + 1),
                    PyArray1::from_vec(py, v).into_any(),
                ));
            }
        }
        for (name, col) in [("payload", &t.payload), ("sigma", &t.sigma)] {
            if let Some(v) = col {
                out.push((name.into(), f(v.clone())));
            }
        }
        out
    }

    /// What the table is called in messages (its file, or a description).
    #[getter]
    fn source(&self) -> &str {
        &self.source
    }

    /// Number of joint columns `q1..qN`.
    #[getter]
    fn n_joints(&self) -> usize {
        self.table.n_joints
    }

    /// Number of distinct poses.
    #[getter]
    fn n_poses(&self) -> usize {
        self.table.n_poses()
    }

    fn __len__(&self) -> usize {
        self.table.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Table({} rows, {} joints, from {})",
            self.table.len(),
            self.table.n_joints,
            self.source
        )
    }
}

/// The columns `x, y, z` (m, tracker frame) and, with an orientation, `qw, qx, qy, qz`, appended to `out`.
fn target_columns<'py>(
    py: Python<'py>,
    position: &[[f64; 3]],
    orientation: Option<&[[f64; 4]]>,
    out: &mut Vec<(String, Bound<'py, PyAny>)>,
) {
    let f = |v: Vec<f64>| PyArray1::from_vec(py, v).into_any();
    for (k, name) in ["x", "y", "z"].iter().enumerate() {
        out.push((name.to_string(), f(position.iter().map(|p| p[k]).collect())));
    }
    if let Some(o) = orientation {
        for (k, name) in ["qw", "qx", "qy", "qz"].iter().enumerate() {
            out.push((name.to_string(), f(o.iter().map(|q| q[k]).collect())));
        }
    }
}

/// Named columns for a DataFrame: `(name, numpy array)` in order.
type Columns<'py> = Vec<(String, Bound<'py, PyAny>)>;

/// A calibrated model: the same content as the command line's MODEL.json.
#[pyclass(frozen, module = "robocal._robocal")]
struct CalibratedModel {
    file: calib::model::file::CalibratedModel,
}

#[pymethods]
impl CalibratedModel {
    /// Loads a model file written by `robocal calibrate --out` or `save`.
    #[staticmethod]
    fn load(py: Python<'_>, path: &str) -> PyResult<Self> {
        let file = quick(
            py,
            calib::model::file::CalibratedModel::load(Path::new(path)).map_err(CliError::from),
        )?;
        Ok(CalibratedModel { file })
    }

    /// Writes the model file (atomically: a temporary file in the same folder, then renamed).
    fn save(&self, py: Python<'_>, path: &str) -> PyResult<()> {
        let text = self.file.to_json();
        quick(
            py,
            sim::io::write_atomic(Path::new(path), text.as_bytes()).map_err(CliError::from),
        )
    }

    /// The model file's JSON text.
    fn to_json(&self) -> String {
        self.file.to_json()
    }

    /// Predictions for the rows of `table` (joint values and whatever the model's causes read; x, y,
    /// z ignored) as `robocal predict`: `(columns, warnings)` with columns `pose, x, y, z` and, with
    /// orientation, `qw, qx, qy, qz` (tracker frame, m).
    fn predict<'py>(
        &self,
        py: Python<'py>,
        table: &Table,
    ) -> PyResult<Vec<(String, Bound<'py, PyAny>)>> {
        let (preds, warnings) = work(py, || {
            let mut predictor = Predictor::from_file(&self.file)?;
            let warnings =
                predict::check_configurations(&table.table, &predictor.model, &table.source)?;
            let preds = predictor.predict_table(&table.table, &table.source)?;
            Ok((preds, warnings))
        })?;
        warn(py, &warnings, 2)?;
        let mut out = vec![(
            "pose".to_string(),
            PyArray1::from_vec(py, preds.pose).into_any(),
        )];
        target_columns(py, &preds.position, preds.orientation.as_deref(), &mut out);
        if let Some(sd) = preds.sigma_m {
            out.push(("sigma_m".to_string(), PyArray1::from_vec(py, sd).into_any()));
        }
        let outside: Vec<i64> = preds.outside_support.iter().map(|&o| o as i64).collect();
        out.push((
            "outside_support".to_string(),
            PyArray1::from_vec(py, outside).into_any(),
        ));
        Ok(out)
    }

    /// `robocal predict` from the file `data` to the CSV file `out`, streamed in pieces of
    /// `chunk_rows` rows (bounded memory, whatever the file's length): `(rows, outside_support)`.
    fn predict_file(
        &self,
        py: Python<'_>,
        data: &str,
        out: &str,
        chunk_rows: usize,
    ) -> PyResult<(usize, usize)> {
        if chunk_rows == 0 {
            return Err(raise(
                py,
                CliError::Input("chunk_rows=0: a piece holds at least 1 row".into()),
            ));
        }
        let summary = work(py, || {
            let mut predictor = Predictor::from_file(&self.file)?;
            predict::predict_streaming(&mut predictor, Path::new(data), Path::new(out), chunk_rows)
        })?;
        Ok((summary.rows, summary.outside_support))
    }

    /// Compensated joints for the rows of `table` as `robocal compensate` with the value flags
    /// `args` (`["--program"]`, `["--frame=base"]`): `(columns, failures)` with columns `pose,
    /// q1..qN, residual_m, outside_support, converged` and the input's context columns; `failures`
    /// the one-line messages naming each row not reached (also issued as `DataWarning`s).
    fn compensate<'py>(
        &self,
        py: Python<'py>,
        table: &Table,
        args: Vec<String>,
    ) -> PyResult<(Columns<'py>, Vec<String>)> {
        let options: comp_cli::Options = quick(py, flags::parse("compensate", &args))?;
        let (c, warnings) = work(py, || {
            let robot = self.file.robot_model()?;
            let warnings = predict::check_configurations(&table.table, &robot, &table.source)?;
            let c = comp_cli::compensate(&self.file, &table.table, &table.source, &options)?;
            Ok((c, warnings))
        })?;
        warn(py, &warnings, 2)?;
        let failures = comp_cli::failure_lines(&c, &table.source, usize::MAX);
        warn(py, &failures, 2)?;
        let f = |v: Vec<f64>| PyArray1::from_vec(py, v).into_any();
        let i = |v: Vec<i64>| PyArray1::from_vec(py, v).into_any();
        let mut out = vec![("pose".to_string(), i(c.pose.clone()))];
        for j in 0..c.nq {
            out.push((
                format!("q{}", j + 1),
                f(c.solutions.iter().map(|s| s.q[j]).collect()),
            ));
        }
        out.push((
            "residual_m".into(),
            f(c.solutions.iter().map(|s| s.residual_m).collect()),
        ));
        out.push((
            "outside_support".into(),
            i(c.outside_support.iter().map(|&o| i64::from(o)).collect()),
        ));
        out.push((
            "converged".into(),
            i(c.solutions
                .iter()
                .map(|s| i64::from(s.converged()))
                .collect()),
        ));
        for (name, values) in &c.context {
            if name.starts_with("dir") || name == "campaign" {
                out.push((name.clone(), i(values.iter().map(|&v| v as i64).collect())));
            } else {
                out.push((name.clone(), f(values.clone())));
            }
        }
        Ok((out, failures))
    }

    /// The calibrated robot's name.
    #[getter]
    fn robot(&self) -> String {
        self.file.robot.name.clone()
    }

    /// The fitted model (`kinematic`, `kinematic+joint_compliance`, …).
    #[getter]
    fn model(&self) -> String {
        self.file.model.name()
    }
}

/// Calibrates as `robocal calibrate`: `args` are its value flags (`["--model=auto", "--seed=3"]`).
/// Returns `(model or None, report JSON text, failure message or None)`; warnings about the data are
/// issued as `DataWarning`s.
#[pyfunction]
#[pyo3(signature = (robot, data, test, args))]
fn calibrate(
    py: Python<'_>,
    robot: &Robot,
    data: &Table,
    test: Option<&Table>,
    args: Vec<String>,
) -> PyResult<(Option<CalibratedModel>, String, Option<String>)> {
    let options: cal_cli::Options = quick(py, flags::parse("calibrate", &args))?;
    let robot = &robot.robot;
    let (outcome, warnings) = work(py, || {
        let whole =
            measurement_table::whole_chain(&data.table, &robot.model, Path::new(&data.source))?;
        let mut warnings = robocal::cli::shared::check_table(&whole, &robot.model, &data.source)?;
        let test_whole = match test {
            Some(t) => Some(measurement_table::whole_chain(
                &t.table,
                &robot.model,
                Path::new(&t.source),
            )?),
            None => None,
        };
        if let (Some(t), Some(w)) = (test, &test_whole) {
            warnings.extend(robocal::cli::shared::check_table(
                w,
                &robot.model,
                &t.source,
            )?);
        }
        let outcome = cal_cli::calibrate(
            robot,
            cal_cli::Named {
                table: &whole,
                name: &data.source,
            },
            test.zip(test_whole.as_deref())
                .map(|(t, w)| cal_cli::Named {
                    table: w,
                    name: &t.source,
                }),
            &options,
            &mut |_| {},
            &mut |_| {},
        )?;
        Ok((outcome, warnings))
    })?;
    warn(py, &warnings, 2)?;
    let report = outcome.json(robot, &data.source, None, None);
    let failure = outcome.failure();
    let model = match failure {
        Some(_) => None,
        None => Some(CalibratedModel {
            file: work(py, || {
                Ok(outcome.model_file(
                    robot,
                    cal_cli::Named {
                        table: &data.table,
                        name: &data.source,
                    },
                )?)
            })?,
        }),
    };
    Ok((model, report.to_string(), failure))
}

/// What a calibration returns to Python: the model (`None` on failure), the report JSON text and the
/// failure message.
type Calibrated = (Option<CalibratedModel>, String, Option<String>);

/// Calibrates the file `path` as `robocal calibrate --data PATH --stream STREAM --chunk-rows N` does
/// when that reads it in pieces (`args`: the value flags). Returns `(model or None, report JSON text,
/// failure message or None)`, or `None` when the table is to be held in memory (`never`; `auto` with
/// a small file or options that need it), for the caller to read it; the robot checks' warnings are
/// issued as `DataWarning`s.
/// The `stream=` keyword of the functions that read a file in pieces (`--stream`).
fn stream_mode(
    py: Python<'_>,
    stream: &str,
) -> PyResult<robocal::cli::calibrate_stream::StreamMode> {
    use robocal::cli::calibrate_stream::StreamMode;
    match stream {
        "auto" => Ok(StreamMode::Auto),
        "always" => Ok(StreamMode::Always),
        "never" => Ok(StreamMode::Never),
        other => Err(raise(
            py,
            CliError::Input(format!(
                "stream='{other}': one of 'auto', 'always' or 'never'"
            )),
        )),
    }
}

#[pyfunction]
#[pyo3(signature = (robot, path, args, stream, chunk_rows))]
fn calibrate_file(
    py: Python<'_>,
    robot: &Robot,
    path: String,
    args: Vec<String>,
    stream: &str,
    chunk_rows: usize,
) -> PyResult<Option<Calibrated>> {
    let options: cal_cli::Options = quick(py, flags::parse("calibrate", &args))?;
    let mode = stream_mode(py, stream)?;
    let path = std::path::PathBuf::from(path);
    let robot = &robot.robot;
    let streamed = work(py, || {
        let reason = options.needs_memory(false);
        let (stream, _) = robocal::cli::calibrate_stream::decide_stream(
            mode,
            &path,
            reason.as_deref(),
            &robot.model,
        )?;
        if !stream {
            return Ok(None);
        }
        let s = cal_cli::calibrate_streamed(robot, &path, &options, chunk_rows, &mut |_| {})?;
        Ok(Some(s))
    })?;
    let Some(s) = streamed else {
        return Ok(None);
    };
    warn(py, &s.warnings, 2)?;
    let name = path.display().to_string();
    let mut report = s.outcome.json(robot, &name, None, None);
    report["stream"] = s.json.clone();
    let failure = s.outcome.failure();
    let model = match failure {
        Some(_) => None,
        None => Some(CalibratedModel {
            file: work(py, || {
                Ok(s.outcome.model_file(
                    robot,
                    cal_cli::Named {
                        table: &s.spaced_rows,
                        name: &name,
                    },
                )?)
            })?,
        }),
    };
    Ok(Some((model, report.to_string(), failure)))
}

/// Registers a new campaign as `robocal register`: `args` are its value flags (`["--target"]`).
/// Returns `(model with the campaign registered, the `register --json` document as text)`; warnings about the
/// data are issued as `DataWarning`s.
#[pyfunction]
fn register(
    py: Python<'_>,
    model: &CalibratedModel,
    data: &Table,
    args: Vec<String>,
) -> PyResult<(CalibratedModel, String)> {
    let options: reg_cli::Options = quick(py, flags::parse("register", &args))?;
    let (file, report, warnings) = work(py, || {
        let robot = Predictor::from_file(&model.file)?.model;
        let whole = measurement_table::whole_chain(&data.table, &robot, Path::new(&data.source))?;
        let warnings = robocal::cli::shared::check_table(&whole, &robot, &data.source)?;
        let (file, report) = reg_cli::register(
            &model.file,
            cal_cli::Named {
                table: &whole,
                name: &data.source,
            },
            &options,
        )?;
        let report = reg_cli::json(None, &data.source, None, &report).to_string();
        Ok((file, report, warnings))
    })?;
    warn(py, &warnings, 2)?;
    Ok((CalibratedModel { file }, report))
}

/// Registers the campaign of the file `path` as `robocal register --data PATH --stream STREAM
/// --chunk-rows N` when that reads it in pieces (`args`: the value flags). Returns `(model with the
/// campaign registered, the register --json document as text)`, or `None` when the table is to be
/// held in memory (`never`, or `auto` with a file of at most 262,144 rows), for the caller to read
/// it; the robot checks' warnings are issued as `DataWarning`s.
#[pyfunction]
#[pyo3(signature = (model, path, args, stream, chunk_rows))]
fn register_file(
    py: Python<'_>,
    model: &CalibratedModel,
    path: String,
    args: Vec<String>,
    stream: &str,
    chunk_rows: usize,
) -> PyResult<Option<(CalibratedModel, String)>> {
    let options: reg_cli::Options = quick(py, flags::parse("register", &args))?;
    let mode = stream_mode(py, stream)?;
    let path = std::path::PathBuf::from(path);
    let done = work(py, || {
        let robot = model.file.robot_model()?;
        let (stream, _) = robocal::cli::calibrate_stream::decide_stream(mode, &path, None, &robot)?;
        if !stream {
            return Ok(None);
        }
        Ok(Some(reg_cli::register_streamed(
            &model.file,
            &path,
            &options,
            chunk_rows,
        )?))
    })?;
    let Some((file, report, warnings, info)) = done else {
        return Ok(None);
    };
    warn(py, &warnings, 2)?;
    let mut doc = reg_cli::json(None, &path.display().to_string(), None, &report);
    doc["stream"] = info;
    Ok(Some((CalibratedModel { file }, doc.to_string())))
}

/// Diagnoses as `robocal diagnose`: `args` are its value flags. Returns the diagnose JSON text.
#[pyfunction]
fn diagnose(py: Python<'_>, robot: &Robot, data: &Table, args: Vec<String>) -> PyResult<String> {
    let options: diag_cli::Options = quick(py, flags::parse("diagnose", &args))?;
    let robot = &robot.robot;
    let (text, warnings) = work(py, || {
        let whole =
            measurement_table::whole_chain(&data.table, &robot.model, Path::new(&data.source))?;
        let warnings = robocal::cli::shared::check_table(&whole, &robot.model, &data.source)?;
        let d = diag_cli::run_diagnosis_with(
            &robot.model,
            &whole,
            &data.source,
            &options.resolve()?,
            &mut |_| {},
        )?;
        Ok((diag_cli::json(&d)?.to_string(), warnings))
    })?;
    warn(py, &warnings, 2)?;
    Ok(text)
}

/// Diagnoses the file `path` as `robocal diagnose --data PATH --stream STREAM --sample-rows N
/// --chunk-rows M --json`: `args` are its value flags. Returns the JSON document as text (with its
/// `stream` object) when the file is read in pieces, `None` when `stream` keeps it in memory (the
/// caller reads it as a table).
#[pyfunction]
#[pyo3(signature = (robot, path, args, stream, sample_rows, chunk_rows))]
fn diagnose_file(
    py: Python<'_>,
    robot: &Robot,
    path: String,
    args: Vec<String>,
    stream: &str,
    sample_rows: usize,
    chunk_rows: usize,
) -> PyResult<Option<String>> {
    let options: diag_cli::Options = quick(py, flags::parse("diagnose", &args))?;
    let mode = stream_mode(py, stream)?;
    let path = std::path::PathBuf::from(path);
    let robot = &robot.robot;
    let streamed = work(py, || {
        let streaming = diag_cli::Streaming {
            mode,
            sample_rows,
            chunk_rows,
        };
        diag_cli::diagnose_file(robot, &path, &options.resolve()?, &streaming)
    })?;
    let Some(s) = streamed else {
        return Ok(None);
    };
    warn(py, &s.warnings, 2)?;
    let mut doc = work(py, || diag_cli::json(&s.diagnosis))?;
    doc["stream"] = s.json;
    Ok(Some(doc.to_string()))
}

/// Generates as `robocal generate --scenario SCENARIO --out OUT`: `args` are its value flags. Returns
/// the `generate --json` summary text.
#[pyfunction]
fn generate(py: Python<'_>, scenario: &str, out: &str, args: Vec<String>) -> PyResult<String> {
    let options: gen_cli::Options = quick(py, flags::parse("generate", &args))?;
    work(py, || {
        let summary = gen_cli::generate(Path::new(scenario), Path::new(out), &options, &|_| {})?;
        Ok(gen_cli::summary_json(&summary)?.to_string())
    })
}

/// Plans measurement poses as `robocal plan-poses`: `args` are its value flags, `candidates` the
/// robot's own poses (a table of configurations) or `None` for drawn ones. Returns `(the pose file's
/// CSV text, the plan-poses --json document as text)`.
#[pyfunction]
#[pyo3(signature = (robot, candidates, args))]
fn plan_poses(
    py: Python<'_>,
    robot: &Robot,
    candidates: Option<&Table>,
    args: Vec<String>,
) -> PyResult<(String, String)> {
    let options: plan_cli::Options = quick(py, flags::parse("plan_poses", &args))?;
    work(py, || {
        let model = &robot.robot.model;
        let plan = plan_cli::plan_poses(
            model,
            candidates.map(|t| (&t.table, t.source.as_str())),
            &options,
            false,
        )?;
        let source = candidates.map(|t| t.source.as_str());
        let json = plan_cli::json(model, &options, source, None, &plan).to_string();
        Ok((plan.to_csv(), json))
    })
}

/// The keyword options a command accepts (`calibrate`, `diagnose`, `generate`, `register`,
/// `compensate`, `plan_poses`): its value flags.
#[pyfunction]
fn options(py: Python<'_>, command: &str) -> PyResult<Vec<String>> {
    match command {
        "calibrate" => Ok(flags::keywords::<cal_cli::Options>("calibrate")),
        "diagnose" => Ok(flags::keywords::<diag_cli::Options>("diagnose")),
        "generate" => Ok(flags::keywords::<gen_cli::Options>("generate")),
        "register" => Ok(flags::keywords::<reg_cli::Options>("register")),
        "compensate" => Ok(flags::keywords::<comp_cli::Options>("compensate")),
        "plan_poses" => Ok(flags::keywords::<plan_cli::Options>("plan_poses")),
        other => Err(raise(
            py,
            CliError::Input(format!(
                "'{other}': not one of calibrate, compensate, diagnose, generate, plan_poses, \
                 register"
            )),
        )),
    }
}

/// The names of the built-in robots.
#[pyfunction]
fn builtin_robots() -> Vec<&'static str> {
    sim::robots::BUILTIN.iter().map(|(n, _)| *n).collect()
}

/// The native module.
#[pymodule]
fn _robocal(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Robot>()?;
    m.add_class::<Table>()?;
    m.add_class::<CalibratedModel>()?;
    m.add_function(wrap_pyfunction!(calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate_file, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose_file, m)?)?;
    m.add_function(wrap_pyfunction!(register, m)?)?;
    m.add_function(wrap_pyfunction!(register_file, m)?)?;
    m.add_function(wrap_pyfunction!(generate, m)?)?;
    m.add_function(wrap_pyfunction!(plan_poses, m)?)?;
    m.add_function(wrap_pyfunction!(options, m)?)?;
    m.add_function(wrap_pyfunction!(builtin_robots, m)?)?;
    m.add("VERSION", sim::generate::VERSION)?;
    // The words of `model=`, from calib's registries (the Python docstring is composed from them).
    m.add("CAUSES", robocal::cli::model_words::cause_words())?;
    m.add("LEARNED_KINDS", robocal::cli::model_words::learned_words())?;
    Ok(())
}
