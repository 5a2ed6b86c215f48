//! Tests of the measurement table I/O (`sim::measurement_table`): exact round trips, one-line errors
//! naming file, row and column, checks against a robot, the real data files, deterministic Parquet.

mod common;

use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use sim::SimError;
use sim::measurement_table::{
    self as mt, MIN_SIGMA_M, MeasurementTable, OptionalColumns, Row, check_against_model,
    read_csv_str, write_csv_string, write_parquet_bytes,
};
use std::path::{Path, PathBuf};

/// A fresh empty folder under the system temp dir for one test.
fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("robocal_mt_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Finite doubles that stress formatting: signed zeros, subnormals, extremes, ordinary values.
const EXTREMES: &[f64] = &[
    0.0,
    -0.0,
    5e-324,
    -5e-324,
    2.225_073_858_507_201e-308, // largest subnormal
    2.2250738585072014e-308,    // smallest normal
    1e300,
    -1e300,
    f64::MAX,
    f64::MIN,
    0.1,
    1.0 / 3.0,
    123456789.0,
    1e16,
    1e-5,
    1e23,                                  // not exact: the double nearest to 10²³
    f64::from_bits(0x44B5_2D02_C7E1_4AF7), // the next double up
];

/// A random finite double: one of the extremes, or random bits with a non-maximal exponent.
fn any_f64(rng: &mut StdRng) -> f64 {
    if rng.random_bool(0.3) {
        EXTREMES[rng.random_range(0..EXTREMES.len())]
    } else {
        loop {
            let v = f64::from_bits(rng.random::<u64>());
            if v.is_finite() {
                return v;
            }
        }
    }
}

/// [`any_f64`] within `±bound` (the contract's physical limits): a value beyond is scaled by 2⁻⁶⁴
/// until it fits, which keeps its random mantissa bits.
fn bounded_f64(rng: &mut StdRng, bound: f64) -> f64 {
    let mut v = any_f64(rng);
    while v.abs() > bound {
        v *= 0.5f64.powi(64);
    }
    v
}

/// A random table with the given optional columns (`None`: each drawn at random).
fn random_table(rng: &mut StdRng, cols: Option<OptionalColumns>) -> MeasurementTable {
    let nq = rng.random_range(1..=8usize);
    let rows = rng.random_range(1..=60usize);
    let cols = cols.unwrap_or_else(|| OptionalColumns {
        orientation: rng.random_bool(0.5),
        t: rng.random_bool(0.5),
        temp: rng.random_bool(0.5),
        dir: rng.random_bool(0.5),
        payload: rng.random_bool(0.5),
        sigma: rng.random_bool(0.5),
        campaign: rng.random_bool(0.5),
    });
    let mut t = MeasurementTable::new(nq, cols);
    // Rows sharing a pose id (in one campaign) are repeats of one pose: the same joint values.
    let mut q_of_pose: std::collections::HashMap<(i64, i64), Vec<f64>> = Default::default();
    for _ in 0..rows {
        let pose = match rng.random_range(0..4) {
            0 => i64::MIN,
            1 => i64::MAX,
            _ => rng.random_range(-5..1000),
        };
        let campaign = match rng.random_range(0..4) {
            0 => i64::MIN,
            1 => i64::MAX,
            _ => rng.random_range(-2..3),
        };
        let key = (if cols.campaign { campaign } else { 0 }, pose);
        let fresh: Vec<f64> = (0..nq).map(|_| any_f64(rng)).collect();
        let q = q_of_pose.entry(key).or_insert(fresh).clone();
        let dir: Vec<i8> = (0..nq).map(|_| rng.random_range(-1..=1)).collect();
        let quat = {
            let v: [f64; 4] = std::array::from_fn(|_| rng.random::<f64>() - 0.5);
            let n = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.map(|x| x / n)
        };
        t.push_row(&Row {
            pose,
            q: &q,
            position: [
                bounded_f64(rng, 500.0),
                bounded_f64(rng, 500.0),
                bounded_f64(rng, 500.0),
            ],
            orientation: cols.orientation.then_some(quat),
            t: cols.t.then(|| any_f64(rng)),
            // Within the physical range (−273.15 … 1000 °C); the extreme doubles go in q and t.
            temp: cols.temp.then(|| bounded_f64(rng, 273.15)),
            dir: cols.dir.then_some(&dir[..]),
            payload: cols.payload.then(|| bounded_f64(rng, 1000.0).abs()),
            // Within [1e-9, 1] m, the range a tracker's 1-sigma can have.
            sigma: cols
                .sigma
                .then(|| bounded_f64(rng, 1.0).abs().max(MIN_SIGMA_M)),
            campaign: cols.campaign.then_some(campaign),
            branch: None,
        })
        .unwrap();
    }
    t
}

/// Bit-for-bit equality of two tables (`==` would call -0.0 and 0.0 equal).
fn assert_bit_equal(a: &MeasurementTable, b: &MeasurementTable, what: &str) {
    fn bits(v: impl IntoIterator<Item = f64>) -> Vec<u64> {
        v.into_iter().map(f64::to_bits).collect()
    }
    fn opt(v: &Option<Vec<f64>>) -> Option<Vec<u64>> {
        v.as_ref().map(|v| bits(v.iter().copied()))
    }
    assert_eq!(a.n_joints, b.n_joints, "{what}: n_joints");
    assert_eq!(a.pose, b.pose, "{what}: pose");
    assert_eq!(
        bits(a.q.iter().copied()),
        bits(b.q.iter().copied()),
        "{what}: q"
    );
    assert_eq!(
        bits(a.position.iter().flatten().copied()),
        bits(b.position.iter().flatten().copied()),
        "{what}: position"
    );
    assert_eq!(
        a.orientation
            .as_ref()
            .map(|o| bits(o.iter().flatten().copied())),
        b.orientation
            .as_ref()
            .map(|o| bits(o.iter().flatten().copied())),
        "{what}: orientation"
    );
    assert_eq!(opt(&a.t), opt(&b.t), "{what}: t");
    assert_eq!(opt(&a.temp), opt(&b.temp), "{what}: temp");
    assert_eq!(a.dir, b.dir, "{what}: dir");
    assert_eq!(opt(&a.payload), opt(&b.payload), "{what}: payload");
    assert_eq!(opt(&a.sigma), opt(&b.sigma), "{what}: sigma");
    assert_eq!(a.campaign, b.campaign, "{what}: campaign");
    assert_eq!(a.branch_names(), b.branch_names(), "{what}: branch names");
    assert_eq!(
        a.branch.as_ref().map(|b| bits(b.values.iter().copied())),
        b.branch.as_ref().map(|b| bits(b.values.iter().copied())),
        "{what}: branch values"
    );
}

#[test]
fn csv_parquet_csv_round_trip_is_bit_exact() {
    let dir = temp_dir("roundtrip");
    let mut rng = StdRng::seed_from_u64(20250611);
    for case in 0..60 {
        let cols = match case {
            0 => Some(OptionalColumns::NONE),
            1 => Some(OptionalColumns::ALL),
            _ => None,
        };
        let table = random_table(&mut rng, cols);
        let csv1 = write_csv_string(&table).unwrap();
        let from_csv = read_csv_str(&csv1, "mem.csv").unwrap();
        assert_bit_equal(&table, &from_csv, &format!("case {case}: CSV"));

        let pq = dir.join(format!("t{case}.parquet"));
        mt::write(&pq, &from_csv).unwrap();
        let from_pq = mt::read(&pq).unwrap();
        assert_bit_equal(&table, &from_pq, &format!("case {case}: CSV -> Parquet"));

        let csv_path = dir.join(format!("t{case}.csv"));
        mt::write(&csv_path, &from_pq).unwrap();
        let csv2 = std::fs::read_to_string(&csv_path).unwrap();
        assert_eq!(
            csv1, csv2,
            "case {case}: CSV -> Parquet -> CSV text differs"
        );
        assert_bit_equal(
            &table,
            &mt::read(&csv_path).unwrap(),
            &format!("case {case}: file"),
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn csv_text_is_as_specified() {
    // Hand-written expectation: shortest round-trip decimals, always with '.' or an exponent.
    let mut t = MeasurementTable::new(
        2,
        OptionalColumns {
            dir: true,
            sigma: true,
            ..OptionalColumns::NONE
        },
    );
    t.push_row(&Row {
        pose: -3,
        q: &[1e300, -0.0],
        position: [0.1, 1.0, 5e-324],
        dir: Some(&[-1, 1]),
        sigma: Some(1e-5),
        ..Default::default()
    })
    .unwrap();
    t.push_row(&Row {
        pose: 7,
        q: &[1e16, 1e15],
        position: [-123.456, 0.30000000000000004, 2.5],
        dir: Some(&[0, 0]),
        sigma: Some(2e-9),
        ..Default::default()
    })
    .unwrap();
    let expected = "pose,q1,q2,x,y,z,dir1,dir2,sigma\n\
                    -3,1e300,-0.0,0.1,1.0,5e-324,-1,1,1e-5\n\
                    7,1e16,1000000000000000.0,-123.456,0.30000000000000004,2.5,0,0,2e-9\n";
    assert_eq!(write_csv_string(&t).unwrap(), expected);
}

#[test]
fn csv_reader_tolerates_bom_blanks_quotes_crlf_and_extra_columns() {
    let text = "\u{feff} note , pose,z ,y,x,q2,q1,\"dir1\",dir2\r\n\
                \r\n\
                \"a, b\",  4 , 3.0, 2 ,1,  -0.5,0.25,-1,+1\r\n\
                \n\
                \"multi\nline\",5,6e0,7,8,9,10,0,1\n";
    let t = read_csv_str(text, "tolerant.csv").unwrap();
    assert_eq!(t.n_joints, 2);
    assert_eq!(t.pose, vec![4, 5]);
    assert_eq!(t.q, vec![0.25, -0.5, 10.0, 9.0]);
    assert_eq!(t.position, vec![[1.0, 2.0, 3.0], [8.0, 7.0, 6.0]]);
    assert_eq!(t.dir, Some(vec![-1, 1, 0, 1]));
    assert_eq!(
        t.columns(),
        OptionalColumns {
            dir: true,
            ..OptionalColumns::NONE
        }
    );
    // Bytes that are not UTF-8 are fine in an ignored column, and an error in a used one.
    let dir = temp_dir("latin1");
    let p = dir.join("latin1.csv");
    std::fs::write(&p, b"pose,q1,x,y,z,note\n1,0.5,1,2,3,caf\xe9\n").unwrap();
    assert_eq!(mt::read(&p).unwrap().q, vec![0.5]);
    std::fs::write(&p, b"pose,q1,x,y,z\n1,0.5,1,2\xe9,3\n").unwrap();
    let e = mt::read(&p).unwrap_err().to_string();
    assert!(
        e.ends_with("latin1.csv: row 1 (line 2), column y: '2\u{fffd}' is not a number"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
    // An integral float is accepted as a pose id.
    let t = read_csv_str("pose,q1,x,y,z\n12.0,0,0,0,0\n", "f.csv").unwrap();
    assert_eq!(t.pose, vec![12]);
}

/// Checks a CSV error: one line, and each expected fragment present.
fn csv_error(text: &str, expect: &[&str]) {
    let e = read_csv_str(text, "data.csv").expect_err(&format!("no error for:\n{text}"));
    let msg = e.to_string();
    assert!(matches!(e, SimError::Table { .. }), "{msg}");
    assert!(!msg.contains('\n'), "not one line: {msg}");
    for part in expect {
        assert!(msg.contains(part), "'{part}' missing in: {msg}");
    }
}

/// A `sigma` no tracker has — zero, a subnormal such as 4.9e-324 (which made `calibrate` run for
/// minutes: the fuzzing suite's 10-second rule now draws such magnitudes in every column), anything
/// below 1 nm — is a one-line error naming the row and `sigma`, on read and on write; 1 nm is read.
#[test]
fn a_sigma_below_a_nanometre_is_refused() {
    for v in ["4.9e-324", "1e-300", "0", "-0.0", "0.0", "9.99e-10"] {
        csv_error(
            &format!("pose,q1,x,y,z,sigma\n1,0,0,0,0,1e-5\n2,0,0,0,0,{v}\n"),
            &["data.csv: row 2 (line 3), column sigma:", "below 1e-9 m"],
        );
    }
    let t = read_csv_str("pose,q1,x,y,z,sigma\n1,0,0,0,0,1e-9\n", "data.csv").unwrap();
    assert_eq!(t.sigma, Some(vec![MIN_SIGMA_M]));
    let mut t = t;
    t.sigma = Some(vec![5e-324]);
    let e = write_csv_string(&t).unwrap_err().to_string();
    assert!(
        e.contains("row 1, column sigma: 5e-324 m is below 1e-9 m"),
        "{e}"
    );
}

/// A valid CSV with `rows` rows of 3 joints, with `cell` put at `(row, column)` (1-based row).
fn csv_with(rows: usize, at: Option<(usize, &str, &str)>) -> String {
    let header = ["pose", "q1", "q2", "q3", "x", "y", "z"];
    let mut s = header.join(",") + "\n";
    for r in 1..=rows {
        let cells: Vec<String> = header
            .iter()
            .map(|&h| match at {
                Some((row, col, val)) if row == r && col == h => val.to_string(),
                _ if h == "pose" => r.to_string(),
                _ => "0.5".to_string(),
            })
            .collect();
        s += &(cells.join(",") + "\n");
    }
    s
}

#[test]
fn bad_csv_cells_give_one_line_errors_with_row_line_and_column() {
    csv_error(
        &csv_with(20, Some((17, "q3", "abc"))),
        &["data.csv: row 17 (line 18), column q3: 'abc' is not a number"],
    );
    csv_error(
        &csv_with(5, Some((2, "y", "inf"))),
        &["data.csv: row 2 (line 3), column y: 'inf' is not finite"],
    );
    csv_error(
        &csv_with(5, Some((4, "x", "NaN"))),
        &["row 4 (line 5), column x: 'NaN' is not finite"],
    );
    csv_error(
        &csv_with(5, Some((3, "q1", ""))),
        &["row 3 (line 4), column q1: empty cell"],
    );
    csv_error(
        &csv_with(5, Some((5, "pose", "1.5"))),
        &["row 5 (line 6), column pose: '1.5' is not an integer"],
    );
    // A blank line shifts the line number but not the row number.
    let text = csv_with(3, Some((3, "z", "1,5"))).replacen("\n", "\n\n", 1);
    csv_error(
        &text,
        &["data.csv: row 3 (line 5): 8 cells, but the header has 7 (a decimal comma?"],
    );
    csv_error(
        "pose,q1,x,y,z\n1,0,0,0\n",
        &["data.csv: row 1 (line 2): 4 cells, but the header has 5"],
    );
    csv_error(
        "pose,q1,x,y,z,dir1\n1,0,0,0,0,1\n2,0,0,0,0,2\n",
        &["data.csv: row 2 (line 3), column dir1: '2' is not a direction (-1, 0 or +1)"],
    );
    csv_error(
        "pose,q1,x,y,z,sigma\n1,0,0,0,0,1e-5\n2,0,0,0,0,-1e-5\n",
        &["data.csv: row 2 (line 3), column sigma: -1e-5 m is negative"],
    );
    csv_error(
        "pose,q1,x,y,z,payload\n1,0,0,0,0,-2.5\n",
        &["data.csv: row 1 (line 2), column payload: -2.5 kg is negative"],
    );
    // Found in validation after parsing: the line number is still given, blank lines counted.
    csv_error(
        "pose,q1,x,y,z,qw,qx,qy,qz\n\n1,0,0,0,0,1,0,0,0\n2,0,0,0,0,2,0,0,0\n",
        &[
            "data.csv: row 2 (line 4), column qw:",
            "norm 2.000000, not a unit quaternion",
        ],
    );
    csv_error(
        "pose,q1,x,y,z\n1,\"0,0,0,0\n",
        &["data.csv: row 1 (line 2): a quoted cell is not closed"],
    );
}

#[test]
fn bad_csv_structure_gives_one_line_errors_naming_the_column() {
    csv_error(
        "pose,q1,q2,x,y\n1,0,0,0,0\n",
        &["data.csv: column z: missing required column 'z' (columns found: pose, q1, q2, x, y)"],
    );
    csv_error(
        "Pose,q1,x,y,z\n1,0,0,0,0\n",
        &[
            "column pose: missing required column 'pose'",
            "there is 'Pose', but names are case-sensitive",
        ],
    );
    csv_error(
        "pose,x,y,z\n1,0,0,0\n",
        &["data.csv: column q1: missing required column 'q1'"],
    );
    csv_error(
        "pose,q1,q2,q4,x,y,z\n1,0,0,0,0,0,0\n",
        &[
            "data.csv: column q3: missing: joint columns must run q1..qN without a gap (found q1, q2, q4)",
        ],
    );
    csv_error(
        "pose,q0,q1,x,y,z\n1,0,0,0,0,0\n",
        &["data.csv: column q0: joint columns are numbered q1, q2"],
    );
    csv_error(
        "pose,q1,q2,q3,x,y,z,dir1,dir2\n1,0,0,0,0,0,0,1,1\n",
        &["data.csv: column dir3: missing: direction columns must be dir1..dir3"],
    );
    csv_error(
        "pose,q1,x,y,z,dir1,dir2\n1,0,0,0,0,1,1\n",
        &["data.csv: column dir2: there is no joint 2: the file has 1 joint columns"],
    );
    csv_error(
        "pose,q1,x,y,z,qw,qx\n1,0,0,0,0,1,0\n",
        &[
            "data.csv: column qy: missing: an orientation needs all of qw, qx, qy, qz (absent: qy, qz)",
        ],
    );
    csv_error(
        "pose,q1,x,y,z,q1\n1,0,0,0,0,0\n",
        &["data.csv: column q1: the column name appears twice (columns 2 and 6 of the header)"],
    );
    csv_error("pose,q1,x,y,z\n", &["data.csv: no data rows"]);
    csv_error("pose,q1,x,y,z\n\n  \n", &["data.csv: no data rows"]);
    csv_error("", &["data.csv: the file is empty"]);
}

#[test]
fn file_format_follows_the_extension() {
    let dir = temp_dir("ext");
    let t = read_csv_str("pose,q1,x,y,z\n1,0.5,1,2,3\n", "m.csv").unwrap();
    let e = mt::write(&dir.join("out.txt"), &t).unwrap_err().to_string();
    assert!(e.contains("out.txt: unknown table format"), "{e}");
    let e = mt::read(Path::new("some/where/data.xlsx"))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("some/where/data.xlsx: unknown table format"),
        "{e}"
    );
    // Upper-case extensions are accepted.
    mt::write(&dir.join("UP.PARQUET"), &t).unwrap();
    assert_eq!(mt::read(&dir.join("UP.PARQUET")).unwrap(), t);
    // A missing file is an I/O error naming it.
    let e = mt::read(&dir.join("absent.csv")).unwrap_err().to_string();
    assert!(e.contains("absent.csv: cannot read"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn writes_are_atomic_and_refuse_invalid_tables() {
    let dir = temp_dir("atomic");
    let path = dir.join("m.csv");
    std::fs::write(&path, "old contents").unwrap();
    let mut t = read_csv_str("pose,q1,x,y,z\n1,0.5,1,2,3\n", "m.csv").unwrap();
    mt::write(&path, &t).unwrap();
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        "pose,q1,x,y,z\n1,0.5,1.0,2.0,3.0\n"
    );
    // An invalid table is not written and the old file stays.
    t.q[0] = f64::NAN;
    let e = mt::write(&path, &t).unwrap_err().to_string();
    assert!(
        e.contains("m.csv: row 1, column q1: NaN is not finite"),
        "{e}"
    );
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        "pose,q1,x,y,z\n1,0.5,1.0,2.0,3.0\n"
    );
    // No temporary files are left behind.
    let names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, vec!["m.csv".to_string()]);
    // Writing into a folder that does not exist fails cleanly.
    t.q[0] = 0.5;
    let e = mt::write(&dir.join("no/such/dir/m.parquet"), &t).unwrap_err();
    assert!(matches!(e, SimError::Io { .. }), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn parquet_bytes_are_deterministic_and_typed_as_specified() {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let mut rng = StdRng::seed_from_u64(7);
    let table = random_table(&mut rng, Some(OptionalColumns::ALL));
    let a = write_parquet_bytes(&table).unwrap();
    let b = write_parquet_bytes(&table.clone()).unwrap();
    assert_eq!(a, b);
    let dir = temp_dir("determinism");
    let p1 = dir.join("a.parquet");
    let p2 = dir.join("b.parquet");
    mt::write(&p1, &table).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1100)); // a timestamp would now differ
    mt::write(&p2, &table).unwrap();
    assert_eq!(std::fs::read(&p1).unwrap(), a);
    assert_eq!(std::fs::read(&p2).unwrap(), a);

    let reader = SerializedFileReader::new(std::fs::File::open(&p1).unwrap()).unwrap();
    let meta = reader.metadata();
    assert_eq!(meta.num_row_groups(), 1);
    let schema = meta.file_metadata().schema_descr();
    for (i, col) in schema.columns().iter().enumerate() {
        let name = col.name();
        let (physical, logical) = (col.physical_type(), col.logical_type_ref().cloned());
        let expect = if name == "pose" || name == "campaign" {
            "INT64"
        } else if name.starts_with("dir") {
            "INT32" // Int8 is INT32 with the INT(8, signed) logical type
        } else {
            "DOUBLE"
        };
        assert_eq!(physical.to_string(), expect, "column {name}");
        if name.starts_with("dir") {
            assert_eq!(
                logical,
                Some(parquet::basic::LogicalType::Integer(
                    parquet::basic::IntType {
                        bit_width: 8,
                        is_signed: true
                    }
                )),
                "column {name}"
            );
        }
        assert_eq!(
            meta.row_group(0).column(i).compression(),
            parquet::basic::Compression::SNAPPY,
            "column {name}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn large_tables_are_split_into_row_groups_and_csv_chunks() {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    let n = mt::PARQUET_MAX_ROW_GROUP_ROWS + 1000;
    let mut t = MeasurementTable::with_capacity(1, OptionalColumns::NONE, n);
    let mut csv = String::from("pose,q1,x,y,z\n");
    for r in 0..n {
        let v = r as f64 * 1e-3;
        csv += &format!("{r},{v:?},{v:?},{:?},0.5\n", -v);
        t.push_row(&Row {
            pose: r as i64,
            q: &[v],
            position: [v, -v, 0.5],
            ..Default::default()
        })
        .unwrap();
    }
    let dir = temp_dir("rowgroups");
    let p = dir.join("big.parquet");
    mt::write(&p, &t).unwrap();
    let meta = SerializedFileReader::new(std::fs::File::open(&p).unwrap()).unwrap();
    let rg: Vec<i64> = (0..meta.metadata().num_row_groups())
        .map(|i| meta.metadata().row_group(i).num_rows())
        .collect();
    assert_eq!(rg, vec![mt::PARQUET_MAX_ROW_GROUP_ROWS as i64, 1000]);
    let back = mt::read(&p).unwrap();
    assert_bit_equal(&t, &back, "row groups");
    // The CSV is written in parallel chunks of rows; the text is the rows in order.
    let p = dir.join("big.csv");
    mt::write(&p, &t).unwrap();
    assert!(
        std::fs::read_to_string(&p).unwrap() == csv,
        "CSV text differs"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Writes a Parquet file with arbitrary Arrow columns (name, array).
fn write_arrow(path: &Path, cols: Vec<(&str, arrow_array::ArrayRef)>) {
    use arrow_schema::{Field, Schema};
    let fields: Vec<Field> = cols
        .iter()
        .map(|(n, a)| Field::new(*n, a.data_type().clone(), true))
        .collect();
    let batch = arrow_array::RecordBatch::try_new(
        std::sync::Arc::new(Schema::new(fields)),
        cols.into_iter().map(|(_, a)| a).collect(),
    )
    .unwrap();
    let f = std::fs::File::create(path).unwrap();
    let mut w = parquet::arrow::ArrowWriter::try_new(f, batch.schema(), None).unwrap();
    w.write(&batch).unwrap();
    w.close().unwrap();
}

#[test]
fn parquet_reader_accepts_exact_conversions_and_names_bad_cells() {
    use arrow_array::{
        ArrayRef, Float32Array, Float64Array, Int32Array, Int64Array, StringArray, UInt8Array,
    };
    use std::sync::Arc;
    let dir = temp_dir("pqread");
    let f64a = |v: Vec<Option<f64>>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let p = dir.join("ok.parquet");
    write_arrow(
        &p,
        vec![
            (
                "comment",
                Arc::new(StringArray::from(vec!["a", "b"])) as ArrayRef,
            ),
            ("x", Arc::new(Float32Array::from(vec![0.1f32, -2.5]))),
            ("pose", Arc::new(Int32Array::from(vec![3, -4]))),
            // A large exact integer in a joint column (positions are bounded to 1 km).
            ("q1", Arc::new(Int64Array::from(vec![-7i64, 1 << 53]))),
            ("y", Arc::new(UInt8Array::from(vec![1u8, 2]))),
            ("z", f64a(vec![Some(0.25), Some(-0.0)])),
            ("dir1", Arc::new(Float64Array::from(vec![-1.0, 1.0]))),
        ],
    );
    let t = mt::read(&p).unwrap();
    assert_eq!(t.pose, vec![3, -4]);
    assert_eq!(t.q, vec![-7.0, 9007199254740992.0]);
    // 0.1f32 widened exactly is 0.100000001490116119384765625, whose shortest f64 form is this:
    assert_eq!(t.position[0], [0.10000000149011612, 1.0, 0.25]);
    assert_eq!(t.position[1][1], 2.0);
    assert_eq!(t.position[1][2].to_bits(), (-0.0f64).to_bits());
    assert_eq!(t.dir, Some(vec![-1, 1]));

    type Case<'a> = (&'a str, Vec<(&'a str, ArrayRef)>, &'a str);
    let cases: Vec<Case> = vec![
        (
            "null",
            vec![
                ("pose", Arc::new(Int64Array::from(vec![1, 2, 3]))),
                ("q1", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
                ("x", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
                ("y", f64a(vec![Some(0.0), None, Some(0.0)])),
                ("z", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
            ],
            "null.parquet: row 2, column y: missing value (null)",
        ),
        (
            "nan",
            vec![
                ("pose", Arc::new(Int64Array::from(vec![1, 2, 3]))),
                ("q1", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
                ("x", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
                ("y", f64a(vec![Some(0.0), Some(0.0), Some(0.0)])),
                ("z", f64a(vec![Some(0.0), Some(0.0), Some(f64::NAN)])),
            ],
            "nan.parquet: row 3, column z: NaN is not finite",
        ),
        (
            "fractional_pose",
            vec![
                ("pose", f64a(vec![Some(1.0), Some(2.5)])),
                ("q1", f64a(vec![Some(0.0), Some(0.0)])),
                ("x", f64a(vec![Some(0.0), Some(0.0)])),
                ("y", f64a(vec![Some(0.0), Some(0.0)])),
                ("z", f64a(vec![Some(0.0), Some(0.0)])),
            ],
            "fractional_pose.parquet: row 2, column pose: 2.5 is not an integer",
        ),
        (
            "text_joint",
            vec![
                ("pose", Arc::new(Int64Array::from(vec![1]))),
                ("q1", Arc::new(StringArray::from(vec!["0.5"]))),
                ("x", f64a(vec![Some(0.0)])),
                ("y", f64a(vec![Some(0.0)])),
                ("z", f64a(vec![Some(0.0)])),
            ],
            "text_joint.parquet: column q1: has Arrow type Utf8; an integer or floating-point type is required",
        ),
        (
            "inexact",
            vec![
                ("pose", Arc::new(Int64Array::from(vec![1]))),
                ("q1", Arc::new(Int64Array::from(vec![(1i64 << 53) + 1]))),
                ("x", f64a(vec![Some(0.0)])),
                ("y", f64a(vec![Some(0.0)])),
                ("z", f64a(vec![Some(0.0)])),
            ],
            "inexact.parquet: row 1, column q1: 9007199254740993 cannot be represented exactly",
        ),
        (
            "missing",
            vec![
                ("pose", Arc::new(Int64Array::from(vec![1]))),
                ("q1", f64a(vec![Some(0.0)])),
                ("x", f64a(vec![Some(0.0)])),
                ("z", f64a(vec![Some(0.0)])),
            ],
            "missing.parquet: column y: missing required column 'y'",
        ),
        (
            "empty",
            vec![
                ("pose", Arc::new(Int64Array::from(Vec::<i64>::new()))),
                ("q1", f64a(vec![])),
                ("x", f64a(vec![])),
                ("y", f64a(vec![])),
                ("z", f64a(vec![])),
            ],
            "empty.parquet: no data rows",
        ),
    ];
    for (name, cols, expect) in cases {
        let p = dir.join(format!("{name}.parquet"));
        write_arrow(&p, cols);
        let msg = mt::read(&p).unwrap_err().to_string();
        assert!(!msg.contains('\n'), "{msg}");
        assert!(msg.contains(expect), "expected '{expect}' in: {msg}");
    }
    let p = dir.join("garbage.parquet");
    std::fs::write(&p, "pose,q1,x,y,z\n").unwrap();
    let msg = mt::read(&p).unwrap_err().to_string();
    assert!(
        msg.contains("garbage.parquet: not a readable Parquet file"),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn builder_and_pose_helpers() {
    let mut t = MeasurementTable::new(
        2,
        OptionalColumns {
            t: true,
            ..OptionalColumns::NONE
        },
    );
    for (pose, q0) in [(5, 0.1), (2, 0.2), (5, 0.3), (9, 0.4), (2, 0.5)] {
        t.push_row(&Row {
            pose,
            q: &[q0, -q0],
            position: [q0, 0.0, 1.0],
            t: Some(q0 * 10.0),
            ..Default::default()
        })
        .unwrap();
    }
    assert_eq!(t.len(), 5);
    assert!(!t.is_empty());
    assert_eq!(t.q_row(2), &[0.3, -0.3]);
    assert_eq!(t.dir_row(2), None);
    assert_eq!(t.pose_ids(), vec![5, 2, 9]);
    assert_eq!(t.n_poses(), 3);
    assert_eq!(
        t.rows_by_pose(),
        vec![(5, vec![0, 2]), (2, vec![1, 4]), (9, vec![3])]
    );
    let s = t.select_rows(&[4, 0]);
    assert_eq!(s.pose, vec![2, 5]);
    assert_eq!(s.q, vec![0.5, -0.5, 0.1, -0.1]);
    assert_eq!(s.t, Some(vec![5.0, 1.0]));
    assert_eq!(t.payload_or_zero(0), 0.0);
    t.validate_shape().unwrap();

    // Mismatched rows are refused and leave the table unchanged.
    let e = t
        .push_row(&Row {
            q: &[0.0],
            t: Some(0.0),
            ..Default::default()
        })
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("row 6, column q: 1 joint values for a table of 2 joints"),
        "{e}"
    );
    let e = t
        .push_row(&Row {
            q: &[0.0, 0.0],
            ..Default::default()
        })
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("column t: the table has this column but the row gives no value"),
        "{e}"
    );
    let e = t
        .push_row(&Row {
            q: &[0.0, 0.0],
            t: Some(1.0),
            sigma: Some(1.0),
            ..Default::default()
        })
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("column sigma: the row gives a value but the table has no such column"),
        "{e}"
    );
    assert_eq!(t.len(), 5);
    t.validate_shape().unwrap();
    t.q.pop();
    let e = t.validate_shape().unwrap_err().to_string();
    assert_eq!(
        e,
        "<measurement table>: column q: 9 values, but 5 rows of 2 joints need 10"
    );

    // Orientation normalisation.
    let o = read_csv_str(
        "pose,q1,x,y,z,qw,qx,qy,qz\n1,0,0,0,0,0.6,0,0,0.8001\n",
        "o.csv",
    )
    .unwrap();
    let u = o.unit_orientation(0).unwrap();
    let n = (0.36f64 + 0.8001 * 0.8001).sqrt();
    assert_eq!(u, [0.6 / n, 0.0, 0.0, 0.8001 / n]);
}

/// A CSV for iiwa7 (7 joints) with all joints at `q` in every row, positions `p`.
fn iiwa_csv(rows: &[([f64; 7], [f64; 3])]) -> String {
    let mut s = String::from("pose,q1,q2,q3,q4,q5,q6,q7,x,y,z\n");
    for (r, (q, p)) in rows.iter().enumerate() {
        let q: Vec<String> = q.iter().map(|v| v.to_string()).collect();
        s += &format!("{r},{},{},{},{}\n", q.join(","), p[0], p[1], p[2]);
    }
    s
}

#[test]
fn check_against_model_applies_the_contract_rules() {
    let iiwa = sim::robots::load_builtin("iiwa7").unwrap();
    let file = Path::new("m.csv");
    let check =
        |text: &str| check_against_model(&read_csv_str(text, "m.csv").unwrap(), &iiwa, file);
    let p = [0.5, 0.1, 0.8];
    let ok = [0.1, -0.2, 0.3, -0.4, 0.5, -0.6, 0.7];
    // A plausible table gives no warning.
    assert_eq!(
        check(&iiwa_csv(&[(ok, p), (ok, [0.4, 0.0, 0.9])])).unwrap(),
        Vec::<String>::new()
    );

    // Joint count.
    let e = check("pose,q1,q2,q3,q4,q5,q6,x,y,z\n1,0,0,0,0,0,0,0,0,0\n")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("m.csv: the file has 6 joint columns (q1..q6), but robot"),
        "{e}"
    );
    assert!(e.contains("has 7 joints"), "{e}");

    // Limits of A2 are ±2.0943951023931953 rad (±120°, iiwa7.urdf). 0.15 rad beyond: error.
    let mut bad = ok;
    bad[1] = 2.0943951023931953 + 0.15;
    let e = check(&iiwa_csv(&[(ok, p), (bad, p)]))
        .unwrap_err()
        .to_string();
    assert!(!e.contains('\n'));
    assert!(
        e.starts_with(
            "m.csv: row 2, column q2: 2.244395102393195 rad is outside the limits \
             [-2.0943951023931953, 2.0943951023931953] rad of joint 'iiwa7_A2' by 0.1500 rad"
        ),
        "{e}"
    );
    // 0.05 rad beyond: one warning for the column, counting rows and naming the worst.
    let mut near = ok;
    near[1] = -2.0943951023931953 - 0.05;
    let mut nearer = ok;
    nearer[1] = -2.0943951023931953 - 0.01;
    let w = check(&iiwa_csv(&[(nearer, p), (near, p), (ok, p)])).unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].starts_with("m.csv: column q2: 2 row(s) outside the limits")
            && w[0].contains("by up to 0.0500 rad (row 2)"),
        "{w:?}"
    );

    // Degrees: the same configurations in degrees (30°, 45°, …) are out of limits, with the hint.
    let deg = |q: [f64; 7]| q.map(f64::to_degrees);
    let e = check(&iiwa_csv(&[
        (deg([0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.1]), p),
        (deg(ok), p),
    ]))
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("row 1, column q1:")
            && e.contains("look like degrees, but radians are expected"),
        "{e}"
    );

    // Millimetres: the same points × 1000.
    let w = check(&iiwa_csv(&[
        (ok, [500.0, 100.0, 800.0]),
        (ok, [400.0, 0.0, 900.0]),
        (ok, [450.0, -50.0, 850.0]),
    ]))
    .unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("columns x, y, z") && w[0].contains("look like millimetres"),
        "{w:?}"
    );
    // A tracker frame a few metres away is not millimetres.
    let far = |d: [f64; 3]| [d[0] + 4.0, d[1] - 3.0, d[2] + 1.5];
    let w = check(&iiwa_csv(&[
        (ok, far([0.5, 0.1, 0.8])),
        (ok, far([0.4, 0.0, 0.9])),
    ]))
    .unwrap();
    assert!(w.is_empty(), "{w:?}");

    // Optional columns: sigma and payload negative are errors (found by validation), temperatures in
    // kelvin and sigma in millimetres are warnings, quaternions off unit by 1e-5 a warning.
    let head = "pose,q1,q2,q3,q4,q5,q6,q7,x,y,z";
    let row = "0,0.1,0.1,0.1,0.1,0.1,0.1,0.1,0.5,0.1,0.8";
    let mut t = read_csv_str(
        &format!("{head},payload,sigma\n{row},0,1e-5\n{row},0,1e-5\n"),
        "m.csv",
    )
    .unwrap();
    t.sigma.as_mut().unwrap()[1] = -1e-5;
    let e = check_against_model(&t, &iiwa, file)
        .unwrap_err()
        .to_string();
    assert_eq!(e, "m.csv: row 2, column sigma: -1e-5 m is negative");
    t.sigma.as_mut().unwrap()[1] = 1e-5;
    t.payload.as_mut().unwrap()[0] = -0.5;
    let e = check_against_model(&t, &iiwa, file)
        .unwrap_err()
        .to_string();
    assert_eq!(e, "m.csv: row 1, column payload: -0.5 kg is negative");
    let w = check(&format!("{head},temp,sigma\n{row},296.15,0.02\n")).unwrap();
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(
        w[0].contains("column sigma") && w[0].contains("millimetres"),
        "{w:?}"
    );
    assert!(
        w[1].contains("column temp") && w[1].contains("kelvin"),
        "{w:?}"
    );
    let w = check(&format!(
        "{head},qw,qx,qy,qz\n{row},1.00001,0,0,0\n{row},1,0,0,0\n"
    ))
    .unwrap();
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(
        w[0].contains("1 row(s) are not unit quaternions") && w[0].contains("row 1"),
        "{w:?}"
    );
    // An in-memory table with a non-finite t is refused.
    let mut t = read_csv_str(&format!("{head},t\n{row},0.5\n"), "m.csv").unwrap();
    t.t.as_mut().unwrap()[0] = f64::INFINITY;
    let e = check_against_model(&t, &iiwa, file)
        .unwrap_err()
        .to_string();
    assert_eq!(e, "m.csv: row 1, column t: inf is not finite");
}

#[test]
fn continuous_joint_in_degrees_is_a_warning() {
    // A two-joint planar arm whose first joint is continuous (no limits).
    let urdf = r#"<robot name="planar">
      <link name="base"/><link name="l1"/><link name="l2"/>
      <joint name="j1" type="continuous"><parent link="base"/><child link="l1"/>
        <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/></joint>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
    </robot>"#;
    let model = sim::urdf::load_str(urdf, "planar.urdf", &sim::ChainSpec::default()).unwrap();
    let t = read_csv_str(
        "pose,q1,q2,x,y,z\n1,90,0.5,0.3,0,0.1\n2,-45,0.5,0.2,0.2,0.1\n",
        "c.csv",
    )
    .unwrap();
    let w = check_against_model(&t, &model, Path::new("c.csv")).unwrap();
    assert_eq!(
        w,
        vec!["c.csv: column q1: values up to 90 look like degrees, but radians are expected"]
    );
    // Two turns in radians are plausible for a continuous joint.
    let t = read_csv_str("pose,q1,q2,x,y,z\n1,12.5,0.5,0.3,0,0.1\n", "c.csv").unwrap();
    assert!(
        check_against_model(&t, &model, Path::new("c.csv"))
            .unwrap()
            .is_empty()
    );
}

#[test]
fn real_ur5_and_wam_files_read_and_fit_their_robots() {
    let real = common::shared_dir().join("data").join("real");
    // UR5: 1000 rows, 6 joints; first and last rows as printed in the file (hand-copied).
    let ur5 = mt::read(&real.join("ur5_jacobi2025_grid.csv")).unwrap();
    assert_eq!((ur5.len(), ur5.n_joints, ur5.n_poses()), (1000, 6, 1000));
    assert_eq!(ur5.columns(), OptionalColumns::NONE);
    assert_eq!(ur5.pose[0], 0);
    assert_eq!(
        ur5.q_row(0),
        &[
            -0.400261541178,
            -0.763043215642,
            2.36313822612,
            -1.65353053576,
            0.967205357283,
            -0.0969046022443
        ]
    );
    assert_eq!(ur5.position[0], [-0.432471963, -0.009795327, -0.097822432]);
    let model = sim::robots::load_builtin("ur5").unwrap();
    let w = check_against_model(&ur5, &model, Path::new("ur5_jacobi2025_grid.csv")).unwrap();
    assert!(w.is_empty(), "{w:?}");
    // The same data in millimetres is flagged.
    let mut mm = ur5.clone();
    mm.position
        .iter_mut()
        .for_each(|p| *p = p.map(|v| v * 1000.0));
    let w = check_against_model(&mm, &model, Path::new("ur5_mm.csv")).unwrap();
    assert!(
        w.len() == 1 && w[0].contains("look like millimetres"),
        "{w:?}"
    );

    // WAM: 216 rows, 7 joints.
    let wam = mt::read(&real.join("wam_jacobi2025_grid.csv")).unwrap();
    assert_eq!((wam.len(), wam.n_joints, wam.n_poses()), (216, 7, 216));
    assert_eq!(
        wam.q_row(0),
        &[
            1.938569199,
            -1.533883625,
            -1.621763769,
            2.106329388,
            -0.037957505,
            -1.075866419,
            0.006945619
        ]
    );
    assert_eq!(wam.position[0], [0.571861043, -0.309193192, 0.004519900]);
    let model = sim::robots::load_builtin("wam").unwrap();
    let w = check_against_model(&wam, &model, Path::new("wam_jacobi2025_grid.csv")).unwrap();
    assert!(w.is_empty(), "{w:?}");
    // The other robot does not fit.
    let e = check_against_model(
        &wam,
        &sim::robots::load_builtin("ur5").unwrap(),
        Path::new("w.csv"),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("the file has 7 joint columns (q1..q7), but robot")
            && e.contains("has 6 joints"),
        "{e}"
    );

    // Parquet round trip of real data.
    let dir = temp_dir("real");
    let p = dir.join("wam.parquet");
    mt::write(&p, &wam).unwrap();
    assert_bit_equal(&wam, &mt::read(&p).unwrap(), "wam parquet");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Writes `$TMPDIR/robocal_table.{csv,parquet}` (all optional columns, extreme values) for
/// `scripts/check_readers.py`: `cargo test -p sim --test measurement_table -- --ignored`.
#[test]
#[ignore]
fn write_files_for_check_readers() {
    let mut rng = StdRng::seed_from_u64(99);
    let mut table = random_table(&mut rng, Some(OptionalColumns::ALL));
    while table.len() < 40 {
        table = random_table(&mut rng, Some(OptionalColumns::ALL));
    }
    let base = std::env::temp_dir();
    mt::write(&base.join("robocal_table.parquet"), &table).unwrap();
    mt::write(&base.join("robocal_table.csv"), &table).unwrap();
    let real = common::shared_dir().join("data/real/ur5_jacobi2025_grid.csv");
    let ur5 = mt::read(&real).unwrap();
    mt::write(&base.join("robocal_ur5.parquet"), &ur5).unwrap();
    mt::write(&base.join("robocal_ur5.csv"), &ur5).unwrap();
    eprintln!(
        "wrote {}/robocal_table.{{csv,parquet}} and robocal_ur5.{{csv,parquet}}",
        base.display()
    );
}

/// A large CSV (several MiB, so it is parsed in parallel chunks) with blank lines and CRLF line ends;
/// returns the text, the expected table, and the 1-based line of every data row, counted while writing.
fn big_csv(rows: usize, bad_row: Option<usize>) -> (String, MeasurementTable, Vec<usize>) {
    let mut rng = StdRng::seed_from_u64(3);
    let mut text = String::from("pose,q1,q2,x,y,z,comment\r\n");
    let mut line = 2;
    let mut lines = Vec::with_capacity(rows);
    let mut t = MeasurementTable::new(2, OptionalColumns::NONE);
    for r in 1..=rows {
        if rng.random_bool(0.01) {
            text.push_str("\r\n");
            line += 1;
        }
        let q = [rng.random::<f64>(), -rng.random::<f64>()];
        let p = [rng.random::<f64>(), 1.0, rng.random_range(-5e2..5e2)];
        let q2 = if bad_row == Some(r) {
            "0.5.5".to_string()
        } else {
            format!("{:?}", q[1])
        };
        text += &format!(
            "{},{:?},{q2},{:?},{:?},{:?},note {r}\r\n",
            r, q[0], p[0], p[1], p[2]
        );
        lines.push(line);
        line += 1;
        t.push_row(&Row {
            pose: r as i64,
            q: &q,
            position: p,
            ..Default::default()
        })
        .unwrap();
    }
    (text, t, lines)
}

#[test]
fn large_csv_is_read_in_parallel_chunks_with_exact_rows_and_lines() {
    let (text, expected, _) = big_csv(60_000, None);
    assert!(
        text.len() > 4 << 20,
        "{} bytes: too small to be split",
        text.len()
    );
    let t = read_csv_str(&text, "big.csv").unwrap();
    assert_bit_equal(&expected, &t, "big CSV");
    for bad in [1, 29_999, 59_999] {
        let (text, _, lines) = big_csv(60_000, Some(bad));
        let e = read_csv_str(&text, "big.csv").unwrap_err().to_string();
        let want = format!(
            "big.csv: row {bad} (line {}), column q2: '0.5.5' is not a number",
            lines[bad - 1]
        );
        assert_eq!(e, want);
    }
    // An error found after parsing (negative sigma) is located by rescanning: same line numbers.
    let (text, _, lines) = big_csv(60_000, None);
    let mut out = String::new();
    for (i, l) in text.split_inclusive('\n').enumerate() {
        if i == 0 {
            out += &l.replace("comment", "sigma");
        } else if l.trim().is_empty() {
            out += l;
        } else {
            let cut = l.rfind(',').unwrap();
            let row: usize = l[cut + 6..].trim().parse().unwrap();
            out += &l[..cut];
            out += if row == 45_678 {
                ",-1.0\r\n"
            } else {
                ",1e-5\r\n"
            };
        }
    }
    let e = read_csv_str(&out, "big.csv").unwrap_err().to_string();
    assert_eq!(
        e,
        format!(
            "big.csv: row 45678 (line {}), column sigma: -1.0 m is negative",
            lines[45_677]
        )
    );
}

/// Every codec that pandas (pyarrow), polars and DuckDB use (snappy, zstd, gzip, lz4, brotli), with
/// and without dictionary encoding, and the types they write by default: the table reads back
/// bit-exactly. (Before the codecs were compiled in, all but snappy failed with "Disabled feature at
/// compile time".)
#[test]
fn parquet_from_every_common_writer_configuration_reads_back_exactly() {
    use parquet::basic::{BrotliLevel, Compression, GzipLevel, ZstdLevel};
    use parquet::file::properties::WriterProperties;
    let dir = temp_dir("codecs");
    let mut rng = StdRng::seed_from_u64(15);
    let table = random_table(&mut rng, None);
    let reference = dir.join("reference.parquet");
    mt::write(&reference, &table).unwrap();
    let batch = {
        let f = std::fs::File::open(&reference).unwrap();
        let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
            .unwrap()
            .build()
            .unwrap();
        let batches: Vec<_> = reader.map(|b| b.unwrap()).collect();
        arrow_select_concat(&batches)
    };
    let codecs = [
        ("snappy", Compression::SNAPPY),
        ("zstd", Compression::ZSTD(ZstdLevel::default())),
        ("gzip", Compression::GZIP(GzipLevel::default())),
        ("lz4", Compression::LZ4_RAW),
        ("lz4_hadoop", Compression::LZ4),
        ("brotli", Compression::BROTLI(BrotliLevel::default())),
        ("none", Compression::UNCOMPRESSED),
    ];
    for (name, codec) in codecs {
        for dictionary in [false, true] {
            let path = dir.join(format!("{name}_{dictionary}.parquet"));
            let props = WriterProperties::builder()
                .set_compression(codec)
                .set_dictionary_enabled(dictionary)
                .set_max_row_group_row_count(Some(7))
                .build();
            let f = std::fs::File::create(&path).unwrap();
            let mut w =
                parquet::arrow::ArrowWriter::try_new(f, batch.schema(), Some(props)).unwrap();
            w.write(&batch).unwrap();
            w.close().unwrap();
            let back =
                mt::read(&path).unwrap_or_else(|e| panic!("{name}, dictionary {dictionary}: {e}"));
            assert_bit_equal(&table, &back, &format!("{name}, dictionary {dictionary}"));
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The record batches of one file as one batch.
fn arrow_select_concat(batches: &[arrow_array::RecordBatch]) -> arrow_array::RecordBatch {
    assert_eq!(batches.len(), 1, "the reference file is read in one batch");
    batches[0].clone()
}

/// The files `scripts/write_reader_variants.py` writes with pandas (snappy, a categorical `pose`,
/// nullable dtypes), polars (zstd), DuckDB and pyarrow (every codec, int32 `pose`, float32 values) in
/// `$ROBOCAL_READER_VARIANTS` (set by `scripts/test.sh`) read back as the CSV they came from: bit for
/// bit, or, for float32 columns, as the CSV's values rounded to float32.
#[test]
fn parquet_written_by_pandas_polars_and_duckdb_reads_back() {
    let dir = match std::env::var_os("ROBOCAL_READER_VARIANTS") {
        Some(d) => PathBuf::from(d),
        None if std::env::var_os("CI").is_some() => {
            panic!("CI must run scripts/write_reader_variants.py and set ROBOCAL_READER_VARIANTS")
        }
        None => {
            eprintln!("ROBOCAL_READER_VARIANTS not set: no third-party Parquet files to read");
            return;
        }
    };
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("variants.json")).unwrap()).unwrap();
    let source = mt::read(Path::new(manifest["source"].as_str().unwrap())).unwrap();
    let files = manifest["files"].as_object().unwrap();
    assert!(files.len() >= 13, "{} variants", files.len());
    for (name, info) in files {
        let back = mt::read(&dir.join(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut expected = source.clone();
        if info["float32"].as_bool().unwrap() {
            let round = |v: &mut f64| *v = f64::from(*v as f32);
            expected.q.iter_mut().for_each(round);
            expected.position.iter_mut().flatten().for_each(round);
        }
        assert_bit_equal(&expected, &back, name);
    }
}

/// Physically impossible magnitudes and a pose id reused at another configuration are one-line
/// errors naming the row and the column (issue 15); the bounds themselves pass.
#[test]
fn impossible_magnitudes_and_reused_pose_ids_are_errors() {
    csv_error(
        &csv_with(3, Some((2, "y", "1e300"))),
        &["data.csv", "row 2", "column y", "beyond 1000 m"],
    );
    csv_error(
        &csv_with(3, Some((3, "x", "-1200"))),
        &["row 3", "column x", "1.200e3 m"],
    );
    let with = |col: &str, v: &str| {
        // The second row ordinary for both columns (a sigma of 0 is refused: below 1 nm).
        format!("pose,q1,x,y,z,{col}\n0,0.1,0.5,0.5,0.5,{v}\n1,0.2,0.5,0.5,0.5,1e-5\n")
    };
    csv_error(
        &with("payload", "1e6"),
        &["row 1", "column payload", "1e6 kg", "beyond 1000 kg"],
    );
    csv_error(
        &with("sigma", "1e3"),
        &["row 1", "column sigma", "1e3 m", "beyond 1 m"],
    );
    // At the bounds: accepted.
    assert!(read_csv_str(&with("payload", "1000"), "data.csv").is_ok());
    assert!(read_csv_str(&with("sigma", "1"), "data.csv").is_ok());
    assert!(read_csv_str(&csv_with(3, Some((2, "x", "999.9"))), "data.csv").is_ok());
    // A pose id reused: fine at the same joint values (repeats, with encoder noise), an error naming
    // both rows at other ones.
    let repeats = "pose,q1,q2,x,y,z\n7,0.1,0.2,0.5,0.5,0.5\n8,0.3,0.4,0.5,0.5,0.5\n7,0.1000004,0.2,0.5,0.5,0.5\n";
    assert_eq!(read_csv_str(repeats, "data.csv").unwrap().len(), 3);
    let reused =
        "pose,q1,q2,x,y,z\n7,0.1,0.2,0.5,0.5,0.5\n8,0.3,0.4,0.5,0.5,0.5\n7,0.1,0.25,0.5,0.5,0.5\n";
    csv_error(
        reused,
        &[
            "row 3",
            "column pose",
            "pose 7 is reused",
            "q2 is 0.25",
            "0.2 in row 1",
        ],
    );
}

/// Found by the fuzzing suite (`tests/fuzz.rs`, seed 15, the exit-0 listing of its value
/// mutations: a `temp` of 1e15 °C predicted without a word). A temperature below absolute zero or
/// above 1000 °C is a one-line error naming the row and the column; the bounds themselves pass.
#[test]
fn fuzz_found_impossible_temperatures_are_errors() {
    let with =
        |v: &str| format!("pose,q1,x,y,z,temp\n0,0.1,0.5,0.5,0.5,20\n1,0.2,0.5,0.5,0.5,{v}\n");
    for v in ["1e15", "-274", "1000.5"] {
        csv_error(
            &with(v),
            &[
                "data.csv",
                "row 2",
                "column temp",
                "not a robot's temperature",
            ],
        );
    }
    for v in ["-273.15", "1000", "-40", "85"] {
        assert!(read_csv_str(&with(v), "data.csv").is_ok(), "{v}");
    }
}

#[test]
fn campaign_column_is_read_written_and_keys_the_poses() {
    // Two campaigns both number their poses from 0: a pose is (campaign, pose), so pose 0 of campaign
    // 7 may stand at other joint values than pose 0 of campaign 3.
    let text = "pose,q1,q2,x,y,z,campaign\n0,0.1,0.2,1,2,3,3\n1,0.3,0.4,1,2,3,3\n0,0.5,0.6,1,2,3,7\n0,0.1,0.2,1.5,2,3,3\n";
    let t = read_csv_str(text, "c.csv").unwrap();
    assert_eq!(t.campaign, Some(vec![3, 3, 7, 3]));
    assert!(t.columns().campaign);
    assert_eq!(t.campaign_ids(), vec![3, 7]);
    assert_eq!(t.n_poses(), 3);
    assert_eq!(
        t.rows_by_pose(),
        vec![(0, vec![0, 3]), (1, vec![1]), (0, vec![2])]
    );
    assert_eq!(t.pose_key(2), (7, 0));
    assert_eq!(t.row(2).campaign, Some(7));
    // Written last, as an integer, and read back identically from CSV and Parquet.
    let csv = mt::write_csv_string(&t).unwrap();
    assert_eq!(csv.lines().next().unwrap(), "pose,q1,q2,x,y,z,campaign");
    assert!(csv.lines().nth(3).unwrap().ends_with(",7"), "{csv}");
    assert_eq!(read_csv_str(&csv, "c.csv").unwrap(), t);
    let dir = temp_dir("campaign");
    let p = dir.join("c.parquet");
    mt::write(&p, &t).unwrap();
    assert_eq!(mt::read(&p).unwrap(), t);
    // Without the column, the same pose id at other joint values is an error; so is a campaign id
    // that is not an integer.
    let no_column = "pose,q1,q2,x,y,z\n0,0.1,0.2,1,2,3\n0,0.5,0.6,1,2,3\n";
    let e = read_csv_str(no_column, "n.csv").unwrap_err().to_string();
    assert!(
        e.contains("pose 0 is reused with other joint values"),
        "{e}"
    );
    let same_campaign = "pose,q1,q2,x,y,z,campaign\n0,0.1,0.2,1,2,3,1\n0,0.5,0.6,1,2,3,1\n";
    let e = read_csv_str(same_campaign, "s.csv")
        .unwrap_err()
        .to_string();
    assert!(e.contains("row 2") && e.contains("column pose"), "{e}");
    let e = read_csv_str("pose,q1,x,y,z,campaign\n0,0.1,1,2,3,1.5\n", "f.csv")
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("f.csv: row 1 (line 2), column campaign:"),
        "{e}"
    );
    // A float-typed Parquet column with integral values (a pandas default after a merge) reads.
    let q = dir.join("float_campaign.parquet");
    write_arrow(
        &q,
        vec![
            (
                "pose",
                std::sync::Arc::new(arrow_array::Int64Array::from(vec![0, 0])),
            ),
            (
                "q1",
                std::sync::Arc::new(arrow_array::Float64Array::from(vec![0.1, 0.2])),
            ),
            (
                "x",
                std::sync::Arc::new(arrow_array::Float64Array::from(vec![1.0, 1.0])),
            ),
            (
                "y",
                std::sync::Arc::new(arrow_array::Float64Array::from(vec![1.0, 1.0])),
            ),
            (
                "z",
                std::sync::Arc::new(arrow_array::Float64Array::from(vec![1.0, 1.0])),
            ),
            (
                "campaign",
                std::sync::Arc::new(arrow_array::Float64Array::from(vec![1.0, 2.0])),
            ),
        ],
    );
    assert_eq!(mt::read(&q).unwrap().campaign, Some(vec![1, 2]));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Every piece of `chunks` is the whole read's rows at its place, bit for bit, and the pieces cover
/// the file in order.
fn assert_chunks_are_the_table(chunks: mt::TableChunks, whole: &MeasurementTable, what: &str) {
    let mut next = 0usize;
    let mut pieces = 0usize;
    for chunk in chunks {
        let chunk = chunk.unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(chunk.first_row, next, "{what}: pieces in order");
        assert!(!chunk.table.is_empty(), "{what}: empty piece");
        let rows: Vec<usize> = (next..next + chunk.table.len()).collect();
        assert_bit_equal(&chunk.table, &whole.select_rows(&rows), what);
        next += chunk.table.len();
        pieces += 1;
    }
    assert_eq!(next, whole.len(), "{what}: every row read");
    assert!(pieces >= 1);
}

#[test]
fn streamed_pieces_are_the_whole_table_in_both_formats() {
    let dir = temp_dir("chunks");
    let mut rng = StdRng::seed_from_u64(20261203);
    for rep in 0..6 {
        // Enough rows for several CSV pieces of the smallest block (4 KiB); pose ids renumbered so
        // that the drawn tables' rows do not repeat one another's ids.
        let first = random_table(&mut rng, None);
        let mut table = MeasurementTable::new(first.n_joints, first.columns());
        let mut part = first;
        while table.len() < 400 {
            for r in 0..part.len() {
                let mut row = part.row(r);
                row.pose = table.len() as i64;
                table.push_row(&row).unwrap();
            }
            part = random_table(&mut rng, Some(table.columns()));
            if part.n_joints != table.n_joints {
                part = MeasurementTable::new(table.n_joints, table.columns());
            }
        }
        let csv = dir.join(format!("t{rep}.csv"));
        let parquet = dir.join(format!("t{rep}.parquet"));
        mt::write(&csv, &table).unwrap();
        mt::write(&parquet, &table).unwrap();
        // Quoted cells (with a line end inside a quoted ignored column) in the CSV variant.
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines();
        let mut quoted = format!("{},\"note\"\n", lines.next().unwrap());
        for (k, l) in lines.enumerate() {
            quoted += &format!("{l},\"row {k}\nsecond line, \"\"quoted\"\"\"\n");
        }
        let quoted_path = dir.join(format!("q{rep}.csv"));
        std::fs::write(&quoted_path, quoted).unwrap();
        for path in [&csv, &parquet, &quoted_path] {
            let whole = mt::read(path).unwrap();
            assert_bit_equal(&whole, &table, "whole read");
            for rows in [1, 7, 64, 100_000] {
                let what = format!("{} in pieces of {rows}", path.display());
                assert_chunks_are_the_table(mt::read_chunks(path, rows).unwrap(), &table, &what);
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn streamed_errors_name_the_file_wide_row_and_line() {
    let dir = temp_dir("chunk_errors");
    // Row 250 of 300 (line 251 with the header; one blank line before the data: 252).
    let text = csv_with(300, Some((250, "q2", "abc"))).replacen("\n", "\n\n", 1);
    let path = dir.join("data.csv");
    std::fs::write(&path, &text).unwrap();
    let whole = mt::read(&path).unwrap_err().to_string();
    for rows in [1, 16, 100_000] {
        let e = mt::read_chunks(&path, rows)
            .unwrap()
            .find_map(Result::err)
            .expect("an error")
            .to_string();
        assert_eq!(e, whole, "pieces of {rows}");
        assert!(e.contains("row 250 (line 252), column q2"), "{e}");
    }
    // Found by the validation of a piece: a non-unit quaternion in row 290.
    let n = 300;
    let f64s = |f: &dyn Fn(usize) -> f64| -> arrow_array::ArrayRef {
        std::sync::Arc::new(arrow_array::Float64Array::from_iter_values((0..n).map(f)))
    };
    let qw = |r: usize| if r == 289 { 2.0 } else { 1.0 };
    let parquet = dir.join("data.parquet");
    write_arrow(
        &parquet,
        vec![
            (
                "pose",
                std::sync::Arc::new(arrow_array::Int64Array::from_iter_values(0..n as i64)),
            ),
            ("q1", f64s(&|_| 0.1)),
            ("x", f64s(&|_| 1.0)),
            ("y", f64s(&|_| 2.0)),
            ("z", f64s(&|_| 3.0)),
            ("qw", f64s(&qw)),
            ("qx", f64s(&|_| 0.0)),
            ("qy", f64s(&|_| 0.0)),
            ("qz", f64s(&|_| 0.0)),
        ],
    );
    let mut text = String::from("pose,q1,x,y,z,qw,qx,qy,qz\n");
    for r in 0..n {
        text += &format!("{r},0.1,1,2,3,{},0,0,0\n", qw(r));
    }
    let csv = dir.join("bad.csv");
    std::fs::write(&csv, text).unwrap();
    for path in [&parquet, &csv] {
        let whole = mt::read(path).unwrap_err().to_string();
        assert!(whole.contains("row 290"), "{whole}");
        for rows in [1, 16, 100_000] {
            let e = mt::read_chunks(path, rows)
                .unwrap()
                .find_map(Result::err)
                .expect("an error")
                .to_string();
            assert_eq!(e, whole, "{} in pieces of {rows}", path.display());
        }
    }
    // No data rows: one error, then the end.
    let empty = dir.join("empty.csv");
    std::fs::write(&empty, "pose,q1,x,y,z\n\n").unwrap();
    let mut it = mt::read_chunks(&empty, 10).unwrap();
    assert!(
        it.next()
            .unwrap()
            .unwrap_err()
            .to_string()
            .contains("no data rows")
    );
    assert!(it.next().is_none());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Repeats are checked against the first row of their pose whatever the order: consecutive runs
/// (a stream's order, checked without a map) and poses that come back later (with one) name the
/// same first bad row, and a run that drifts by less than the tolerance a row at a time but more
/// in all is caught against its first row.
#[test]
fn pose_repeats_are_checked_against_the_first_row_in_any_order() {
    let tol = mt::POSE_REPEAT_TOLERANCE;
    let row = |pose: i64, q1: f64| format!("{pose},{q1},0.2,0.5,0.5,0.5\n");
    // Pose 1 drifts by 0.6 tol a row: rows 3 and 4 each within tol of the row before, row 4 not
    // of row 2, its first.
    let drift = format!(
        "pose,q1,q2,x,y,z\n{}{}{}{}{}",
        row(0, 0.1),
        row(1, 0.3),
        row(1, 0.3 + 0.6 * tol),
        row(1, 0.3 + 1.2 * tol),
        row(2, 0.5)
    );
    csv_error(
        &drift,
        &["row 4", "column pose", "pose 1 is reused", "in row 2"],
    );
    // The same bad run followed by a pose that comes back out of order: still row 4 first.
    let then_back = format!("{drift}{}", row(0, 0.9));
    csv_error(&then_back, &["row 4", "pose 1 is reused", "in row 2"]);
    // A pose that comes back out of order at other joint values: named against its first row.
    let back = format!(
        "pose,q1,q2,x,y,z\n{}{}{}{}",
        row(0, 0.1),
        row(1, 0.3),
        row(2, 0.5),
        row(1, 0.35)
    );
    csv_error(&back, &["row 4", "pose 1 is reused", "in row 2"]);
    // Within the tolerance of the first row, in and out of order: accepted.
    let fine = format!(
        "pose,q1,q2,x,y,z\n{}{}{}{}",
        row(1, 0.3),
        row(1, 0.3 + 0.9 * tol),
        row(0, 0.1),
        row(1, 0.3 - 0.9 * tol)
    );
    assert_eq!(read_csv_str(&fine, "data.csv").unwrap().len(), 4);
}

// ---------------------------------------------------------------------------------------------
// Branch joint columns (`q_<joint name>`): joints of branches off the chain, kept row for row.

/// `table` with branch joint columns `q_<name>` for `names`, one random finite value each per row
/// (the extreme doubles included); rows of one pose get one set of values, as the chain's do.
fn with_branch(rng: &mut StdRng, table: &MeasurementTable, names: &[&str]) -> MeasurementTable {
    let nb = names.len();
    let mut of_pose: std::collections::HashMap<(i64, i64), Vec<f64>> = Default::default();
    let mut values = Vec::with_capacity(table.len() * nb);
    for r in 0..table.len() {
        let fresh: Vec<f64> = (0..nb).map(|_| any_f64(rng)).collect();
        values.extend_from_slice(of_pose.entry(table.pose_key(r)).or_insert(fresh));
    }
    let mut t = table.clone();
    t.branch = Some(mt::BranchColumns {
        names: names.iter().map(|n| n.to_string()).collect(),
        values,
    });
    t.validate_shape().unwrap();
    t
}

/// Names of branch joints as URDFs spell them, a comma and a quote included (CSV quotes them).
const BRANCH_NAMES: &[&str] = &["neck_yaw", "arm2_joint_1", "head,tilt", "say \"cheese\""];

#[test]
fn branch_columns_round_trip_bit_exactly_through_csv_and_parquet() {
    let dir = temp_dir("branch_roundtrip");
    let mut rng = StdRng::seed_from_u64(20260801);
    for case in 0..24 {
        let cols = match case {
            0 => Some(OptionalColumns::NONE),
            1 => Some(OptionalColumns::ALL),
            _ => None,
        };
        let names = &BRANCH_NAMES[..1 + case % BRANCH_NAMES.len()];
        let plain = random_table(&mut rng, cols);
        let table = with_branch(&mut rng, &plain, names);
        let what = format!("case {case}");
        let csv = write_csv_string(&table).unwrap();
        // Written right after q1..qN, quoted where a name needs it.
        let header = csv.lines().next().unwrap();
        let qs: Vec<String> = (1..=table.n_joints).map(|j| format!("q{j}")).collect();
        let mut expect = format!("pose,{},q_neck_yaw", qs.join(","));
        for (name, cell) in [
            ("arm2_joint_1", "q_arm2_joint_1"),
            ("head,tilt", "\"q_head,tilt\""),
            ("say \"cheese\"", "\"q_say \"\"cheese\"\"\""),
        ] {
            if names.contains(&name) {
                expect += &format!(",{cell}");
            }
        }
        expect += ",x,y,z";
        assert!(header.starts_with(&expect), "{what}: {header}");
        let from_csv = read_csv_str(&csv, "mem.csv").unwrap();
        assert_bit_equal(&table, &from_csv, &format!("{what}: CSV"));
        let names_read: Vec<&str> = from_csv.branch_names().iter().map(String::as_str).collect();
        assert_eq!(names_read, names, "{what}");

        let pq = dir.join(format!("t{case}.parquet"));
        mt::write(&pq, &table).unwrap();
        let from_pq = mt::read(&pq).unwrap();
        assert_bit_equal(&table, &from_pq, &format!("{what}: Parquet"));
        assert_eq!(
            write_parquet_bytes(&from_pq).unwrap(),
            std::fs::read(&pq).unwrap()
        );
        assert_eq!(from_pq.column_names(), table.column_names(), "{what}");
        // In the file, the branch columns are Float64, after q1..qN.
        let schema = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(
            std::fs::File::open(&pq).unwrap(),
        )
        .unwrap()
        .schema()
        .clone();
        for (k, name) in names.iter().enumerate() {
            let field = schema.field(1 + table.n_joints + k);
            assert_eq!(field.name(), &format!("q_{name}"), "{what}");
            assert_eq!(
                field.data_type(),
                &arrow_schema::DataType::Float64,
                "{what}"
            );
        }

        let csv_path = dir.join(format!("t{case}.csv"));
        mt::write(&csv_path, &from_pq).unwrap();
        assert_eq!(std::fs::read_to_string(&csv_path).unwrap(), csv, "{what}");
        assert_bit_equal(
            &table,
            &mt::read(&csv_path).unwrap(),
            &format!("{what}: file"),
        );
        // Joint configurations keep them too.
        assert_bit_equal(
            &table,
            &mt::read_configurations(&csv_path).unwrap(),
            &format!("{what}: configurations"),
        );
    }
    // A file without q_ columns has none, and writes as before.
    let t = read_csv_str("pose,q1,x,y,z,qa,q_1x\n0,0.5,1,2,3,7,8\n", "n.csv").unwrap();
    assert_eq!(
        t.branch.as_ref().map(|b| b.names.clone()),
        Some(vec!["1x".to_string()])
    );
    let t = read_csv_str("pose,q1,x,y,z,qa,note\n0,0.5,1,2,3,7,8\n", "n.csv").unwrap();
    assert_eq!(t.branch, None);
    assert_eq!(t.branch_names(), &[] as &[String]);
    assert_eq!(t.branch_row(0), None);
    assert_eq!(
        write_csv_string(&t).unwrap(),
        "pose,q1,x,y,z\n0,0.5,1.0,2.0,3.0\n"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn branch_columns_are_read_from_any_column_position() {
    let text = "q_neck_yaw,pose,x,q2,y,q_hand,z,q1\n\
                0.25,0,1,0.5,2,-0.0,3,0.125\n\
                -1.5,1,1,0.5,2,2e-3,3,0.125\n";
    let t = read_csv_str(text, "any.csv").unwrap();
    assert_eq!(t.n_joints, 2);
    assert_eq!(
        t.branch_names(),
        &["neck_yaw".to_string(), "hand".to_string()]
    );
    assert_eq!(t.branch_row(0), Some(&[0.25, -0.0][..]));
    assert_eq!(t.branch_row(1), Some(&[-1.5, 2e-3][..]));
    assert_eq!(t.row(1).branch, Some(&[-1.5, 2e-3][..]));
    assert_eq!(t.q, vec![0.125, 0.5, 0.125, 0.5]);
    assert_eq!(
        write_csv_string(&t).unwrap(),
        "pose,q1,q2,q_neck_yaw,q_hand,x,y,z\n\
         0,0.125,0.5,0.25,-0.0,1.0,2.0,3.0\n\
         1,0.125,0.5,-1.5,0.002,1.0,2.0,3.0\n"
    );
}

#[test]
fn branch_columns_come_in_every_streamed_piece() {
    let dir = temp_dir("branch_chunks");
    let mut rng = StdRng::seed_from_u64(20260802);
    // 302 rows with three branch joints: pieces of 7 or 64 rows (Parquet) leave a shorter last piece
    // (302 % 7 = 1, 302 % 64 = 46); CSV pieces of 4 KiB or 16 KiB of text split wherever the bytes fall.
    let cols = OptionalColumns {
        dir: true,
        campaign: true,
        ..OptionalColumns::NONE
    };
    let mut table = MeasurementTable::new(3, cols);
    for r in 0..302 {
        let q = [r as f64 * 1e-3, -0.5, 0.25];
        table
            .push_row(&Row {
                pose: r,
                q: &q,
                position: [1.0, 2.0, 3.0],
                dir: Some(&[1, 0, -1]),
                campaign: Some(r % 2),
                ..Default::default()
            })
            .unwrap();
    }
    let table = with_branch(&mut rng, &table, &BRANCH_NAMES[..3]);
    let csv = dir.join("b.csv");
    let parquet = dir.join("b.parquet");
    mt::write(&csv, &table).unwrap();
    mt::write(&parquet, &table).unwrap();
    for path in [&csv, &parquet] {
        let whole = mt::read(path).unwrap();
        assert_bit_equal(&whole, &table, "whole read");
        for rows in [7, 64] {
            let what = format!("{} in pieces of {rows}", path.display());
            let chunks = mt::read_chunks(path, rows).unwrap();
            assert_eq!(chunks.branch_names(), table.branch_names(), "{what}");
            let lens: Vec<usize> = mt::read_chunks(path, rows)
                .unwrap()
                .map(|c| c.unwrap().table.len())
                .collect();
            assert!(lens.len() > 1, "{what}: one piece");
            assert!(
                lens.iter().any(|&n| n != lens[0]),
                "{what}: pieces of equal size {lens:?}"
            );
            for chunk in mt::read_chunks(path, rows).unwrap() {
                let chunk = chunk.unwrap();
                assert_eq!(chunk.table.branch_names(), table.branch_names(), "{what}");
                for r in 0..chunk.table.len() {
                    assert_eq!(
                        chunk.table.branch_row(r),
                        whole.branch_row(chunk.first_row + r),
                        "{what}: row {}",
                        chunk.first_row + r
                    );
                }
            }
            assert_chunks_are_the_table(mt::read_chunks(path, rows).unwrap(), &table, &what);
            let configs = mt::read_configuration_chunks(path, rows).unwrap();
            assert_eq!(configs.branch_names(), table.branch_names(), "{what}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn from_columns_keeps_branch_columns() {
    use mt::{Column, ColumnValues};
    let col = |name, values| Column {
        name,
        values,
        first_null: None,
    };
    let csv = "pose,q1,q_neck_yaw,x,y,z,q_hand,note\n0,0.5,0.25,0.1,0.2,0.3,-1.0,a\n\
               1,0.25,-0.125,1.5,-0.5,0.75,3.0,b\n";
    let expected = read_csv_str(csv, "m.csv").unwrap();
    assert_eq!(expected.branch_row(1), Some(&[-0.125, 3.0][..]));
    let cols = [
        col("pose", ColumnValues::I64(&[0, 1])),
        col("q_hand", ColumnValues::I32(&[-1, 3])),
        col("q1", ColumnValues::F64(&[0.5, 0.25])),
        col("x", ColumnValues::F64(&[0.1, 1.5])),
        col("y", ColumnValues::F64(&[0.2, -0.5])),
        col("z", ColumnValues::F64(&[0.3, 0.75])),
        col("q_neck_yaw", ColumnValues::F32(&[0.25, -0.125])),
        col("note", ColumnValues::Other("object")),
    ];
    let t = mt::from_columns(&cols, "df").unwrap();
    // Header order: q_hand before q_neck_yaw here.
    assert_eq!(
        t.branch_names(),
        &["hand".to_string(), "neck_yaw".to_string()]
    );
    assert_eq!(t.branch_row(0), Some(&[-1.0, 0.25][..]));
    assert_eq!(t.branch_row(1), Some(&[3.0, -0.125][..]));
    assert_eq!(
        (t.pose.clone(), t.q.clone()),
        (expected.pose.clone(), expected.q.clone())
    );
    let c = mt::configurations_from_columns(&cols[..3], "df").unwrap();
    assert_eq!(c.branch_row(1), Some(&[3.0][..]));
    // Errors as for a file.
    let mut bad = cols;
    bad[6] = col("q_neck_yaw", ColumnValues::F64(&[0.5, f64::INFINITY]));
    let e = mt::from_columns(&bad, "df").unwrap_err().to_string();
    assert_eq!(e, "df: row 2, column q_neck_yaw: inf is not finite");
    bad[6] = col("q_neck_yaw", ColumnValues::Other("object"));
    let e = mt::from_columns(&bad, "df").unwrap_err().to_string();
    assert_eq!(
        e,
        "df: column q_neck_yaw: has type object; an integer or floating-point type is required"
    );
    bad[6] = Column {
        first_null: Some(0),
        ..col("q_neck_yaw", ColumnValues::F64(&[0.5, 0.5]))
    };
    let e = mt::from_columns(&bad, "df").unwrap_err().to_string();
    assert_eq!(
        e,
        "df: row 1, column q_neck_yaw: missing value (null): a number is required"
    );
}

#[test]
fn bad_branch_columns_give_one_line_errors_naming_row_and_column() {
    let with =
        |cell: &str| format!("pose,q1,x,y,z,q_neck_yaw\n0,0.5,1,2,3,0.25\n1,0.5,1,2,3,{cell}\n");
    csv_error(
        &with("abc"),
        &["data.csv: row 2 (line 3), column q_neck_yaw: 'abc' is not a number"],
    );
    csv_error(
        &with("inf"),
        &["data.csv: row 2 (line 3), column q_neck_yaw: 'inf' is not finite"],
    );
    csv_error(
        &with("NaN"),
        &["data.csv: row 2 (line 3), column q_neck_yaw: 'NaN' is not finite"],
    );
    csv_error(
        &with(""),
        &["data.csv: row 2 (line 3), column q_neck_yaw: empty cell: a number is required"],
    );
    // The header: `q_` without a name, a name of blanks, a branch joint twice.
    csv_error(
        "pose,q1,q_,x,y,z\n0,0.5,0.25,1,2,3\n",
        &["data.csv: column q_: a branch joint column needs the joint's name after 'q_'"],
    );
    csv_error(
        "pose,q1,\"q_  \",x,y,z\n0,0.5,0.25,1,2,3\n",
        &["data.csv: column q_  : a branch joint column needs the joint's name"],
    );
    csv_error(
        "pose,q1,q_neck,x,y,z,q_neck\n0,0.5,0.25,1,2,3,0.25\n",
        &["data.csv: column q_neck: the column name appears twice (columns 3 and 7 of the header)"],
    );
    // Parquet: a null, a NaN, text.
    use arrow_array::{ArrayRef, Float64Array, Int64Array, StringArray};
    use std::sync::Arc;
    let dir = temp_dir("branch_errors");
    let f64a = |v: Vec<Option<f64>>| Arc::new(Float64Array::from(v)) as ArrayRef;
    let base = |branch: ArrayRef| {
        vec![
            (
                "pose",
                Arc::new(Int64Array::from(vec![1, 2, 3])) as ArrayRef,
            ),
            ("q1", f64a(vec![Some(0.0); 3])),
            ("x", f64a(vec![Some(0.0); 3])),
            ("y", f64a(vec![Some(0.0); 3])),
            ("z", f64a(vec![Some(0.0); 3])),
            ("q_neck_yaw", branch),
        ]
    };
    for (name, branch, expect) in [
        (
            "null",
            f64a(vec![Some(0.0), None, Some(0.0)]),
            "null.parquet: row 2, column q_neck_yaw: missing value (null): a number is required",
        ),
        (
            "nan",
            f64a(vec![Some(0.0), Some(0.0), Some(f64::NAN)]),
            "nan.parquet: row 3, column q_neck_yaw: NaN is not finite",
        ),
        (
            "text",
            Arc::new(StringArray::from(vec!["a", "b", "c"])) as ArrayRef,
            "text.parquet: column q_neck_yaw: has Arrow type Utf8; an integer or floating-point type is required",
        ),
    ] {
        let p = dir.join(format!("{name}.parquet"));
        write_arrow(&p, base(branch));
        let msg = mt::read(&p).unwrap_err().to_string();
        assert!(msg.ends_with(expect), "expected '{expect}' in: {msg}");
        let chunked = mt::read_chunks(&p, 1)
            .unwrap()
            .find_map(Result::err)
            .expect("an error")
            .to_string();
        assert_eq!(chunked, msg, "{name}: streamed");
    }
    let p = dir.join("empty_name.parquet");
    write_arrow(
        &p,
        vec![
            ("pose", Arc::new(Int64Array::from(vec![1])) as ArrayRef),
            ("q1", f64a(vec![Some(0.0)])),
            ("x", f64a(vec![Some(0.0)])),
            ("y", f64a(vec![Some(0.0)])),
            ("z", f64a(vec![Some(0.0)])),
            ("q_", f64a(vec![Some(0.0)])),
        ],
    );
    let msg = mt::read(&p).unwrap_err().to_string();
    assert!(
        msg.ends_with(
            "column q_: a branch joint column needs the joint's name after 'q_' (q_<joint name>)"
        ),
        "{msg}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn tables_in_memory_with_bad_branch_columns_are_refused() {
    let mut t = read_csv_str(
        "pose,q1,x,y,z,q_neck_yaw,q_hand\n0,0.5,1,2,3,0.25,1\n1,0.5,1,2,3,-0.25,2\n",
        "m.csv",
    )
    .unwrap();
    t.validate_shape().unwrap();
    let b = |t: &mut MeasurementTable| t.branch.as_mut().unwrap().clone();
    let good = b(&mut t);
    // Shape: one value per branch joint and row; names unique and not empty.
    t.branch.as_mut().unwrap().values.pop();
    assert_eq!(
        t.validate_shape().unwrap_err().to_string(),
        "<measurement table>: column q_neck_yaw: 3 values, but 2 rows of 2 branch joints need 4"
    );
    t.branch = Some(mt::BranchColumns::default());
    let e = t.validate_shape().unwrap_err().to_string();
    assert!(
        e.starts_with("<measurement table>: column q_: branch columns without a joint name"),
        "{e}"
    );
    t.branch = Some(good.clone());
    t.branch.as_mut().unwrap().names[1] = "neck_yaw".into();
    assert_eq!(
        t.validate_shape().unwrap_err().to_string(),
        "<measurement table>: column q_neck_yaw: the branch joint appears twice (branch columns 1 and 2)"
    );
    t.branch.as_mut().unwrap().names[1] = String::new();
    let e = write_csv_string(&t).unwrap_err().to_string();
    assert!(
        e.starts_with("<measurement table>: column q_: a branch joint column needs"),
        "{e}"
    );
    t.branch.as_mut().unwrap().names[1] = " hand".into();
    let e = write_parquet_bytes(&t).unwrap_err().to_string();
    assert!(e.contains("must not start or end with blanks"), "{e}");
    // Values: finite, checked on write.
    t.branch = Some(good.clone());
    t.branch.as_mut().unwrap().values[3] = f64::NEG_INFINITY;
    assert_eq!(
        write_csv_string(&t).unwrap_err().to_string(),
        "<measurement table>: row 2, column q_hand: -inf is not finite"
    );
    t.branch = Some(good);
    write_csv_string(&t).unwrap();

    // push_row: the row's branch values must match the table's branch columns.
    let mut u = t.empty_like(0);
    assert_eq!(u.branch_names(), t.branch_names());
    let row = t.row(1);
    u.push_row(&row).unwrap();
    assert_eq!(u.branch_row(0), Some(&[-0.25, 2.0][..]));
    let e = u
        .push_row(&Row {
            branch: None,
            ..row
        })
        .unwrap_err();
    assert_eq!(
        e.to_string(),
        "<measurement table>: row 2, column q_neck_yaw: the table has this column but the row gives no value"
    );
    let e = u
        .push_row(&Row {
            branch: Some(&[1.0]),
            ..row
        })
        .unwrap_err();
    assert!(
        e.to_string().contains(
            "row 2, column q_neck_yaw: 1 branch joint values for a table of 2 branch joints"
        ),
        "{e}"
    );
    let mut plain = MeasurementTable::new(1, OptionalColumns::NONE);
    let e = plain.push_row(&row).unwrap_err();
    assert!(
        e.to_string().contains(
            "column q_: the row gives branch joint values but the table has no q_ column"
        ),
        "{e}"
    );
    assert_eq!((u.len(), plain.len()), (1, 0));

    // The streaming Parquet writer: parts with the table's branch joints only, names checked.
    let names = t.branch_names().to_vec();
    let mut w = mt::ParquetTableWriter::with_branch_names(
        Vec::new(),
        1,
        OptionalColumns::NONE,
        &names,
        "w.parquet",
    )
    .unwrap();
    w.append(&t.select_rows(&[0])).unwrap();
    let e = w.append(&plain_table()).unwrap_err().to_string();
    assert_eq!(e, "w.parquet: a part with other columns than the table's");
    let mut swapped = t.select_rows(&[1]);
    swapped.branch.as_mut().unwrap().names.reverse();
    assert!(w.append(&swapped).is_err());
    w.append(&t.select_rows(&[1])).unwrap();
    assert_eq!(w.finish().unwrap(), write_parquet_bytes(&t).unwrap());
    let e = mt::ParquetTableWriter::with_branch_names(
        Vec::new(),
        1,
        OptionalColumns::NONE,
        &["a".to_string(), "a".to_string()],
        "w.parquet",
    )
    .err()
    .expect("a duplicated name is refused")
    .to_string();
    assert!(
        e.starts_with("w.parquet: column q_a: the branch joint appears twice"),
        "{e}"
    );
    let mut w =
        mt::ParquetTableWriter::new(Vec::new(), 1, OptionalColumns::NONE, "p.parquet").unwrap();
    assert!(w.append(&t).is_err());
    w.append(&plain_table()).unwrap();
}

/// A valid one-row table of one joint, without optional or branch columns.
fn plain_table() -> MeasurementTable {
    read_csv_str("pose,q1,x,y,z\n7,0.5,1,2,3\n", "p.csv").unwrap()
}

#[test]
fn select_rows_and_drive_columns_keep_each_rows_branch_values() {
    let mut t = MeasurementTable::new(3, OptionalColumns::NONE);
    t.branch = Some(mt::BranchColumns {
        names: vec!["neck_yaw".into(), "arm2_j1".into()],
        values: Vec::new(),
    });
    for r in 0..6 {
        let v = [r as f64, -(r as f64) - 0.5];
        t.push_row(&Row {
            pose: r,
            q: &[0.1 * r as f64, 0.2, 0.3],
            position: [1.0, 2.0, 3.0],
            branch: Some(&v),
            ..Default::default()
        })
        .unwrap();
    }
    let s = t.select_rows(&[4, 1, 4, 0]);
    assert_eq!(s.pose, vec![4, 1, 4, 0]);
    assert_eq!(s.branch_names(), t.branch_names());
    for (k, &r) in [4usize, 1, 4, 0].iter().enumerate() {
        assert_eq!(s.branch_row(k), t.branch_row(r), "selected row {k}");
        assert_eq!(s.branch_row(k), Some(&[r as f64, -(r as f64) - 0.5][..]));
    }
    assert_eq!(s.branch.as_ref().unwrap().values.len(), 8);
    s.validate_shape().unwrap();
    let none = t.select_rows(&[]);
    assert_eq!(none.branch_names(), t.branch_names());
    assert!(none.branch.as_ref().unwrap().values.is_empty());
    // A table of drives: the chain's joint columns change, the branch columns do not.
    let d = mt::drive_columns(t.clone(), &[0, 2]);
    assert_eq!(d.n_joints, 2);
    assert_eq!(d.q_row(3), &[0.30000000000000004, 0.3]);
    assert_eq!(d.branch, t.branch);
}

/// Rows sharing a pose id are repeats of one pose, branches included: their scatter is the measured
/// repeatability, and a branch posed elsewhere loads the chain otherwise. A branch column that
/// differs beyond the tolerance names the pose, the rows and the column; within it, the rows are
/// repeats.
#[test]
fn repeats_of_a_pose_agree_on_the_branch_columns_too() {
    let text = "pose,q1,q2,q_neck_yaw,q_hand,x,y,z\n\
                0,0.1,0.2,0.5,-1.0,1,2,3\n\
                0,0.1,0.2,0.5,-1.2,1,2,3\n";
    let e = read_csv_str(text, "r.csv").unwrap_err().to_string();
    assert!(
        e.contains("r.csv")
            && e.contains("row 2")
            && e.contains(
                "pose 0 is reused with other joint values: q_hand is -1.2 here but -1.0 in row 1"
            ),
        "{e}"
    );
    let close = "pose,q1,q2,q_neck_yaw,q_hand,x,y,z\n\
                 0,0.1,0.2,0.5,-1.0,1,2,3\n\
                 0,0.1,0.2,0.5,-1.0004,1,2,3\n\
                 1,0.1,0.2,0.9,-1.0,1,2,3\n";
    let t = read_csv_str(close, "c.csv").unwrap();
    assert_eq!(t.n_poses(), 2);
}
