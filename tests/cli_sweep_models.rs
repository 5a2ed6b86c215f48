//! `robocal sweep` with models beyond the kinematic one and with the magnitude axis, end to end
//! through the built binary: the stiffness parameters' errors against the simulator's truth in units
//! of their predicted σ, a magnitude of 0 leaving the effect out of the truth, and the shards of a
//! non-kinematic sweep merging to the bytes of a single run (both tables). Seeds are drawn per run
//! and printed (`ROBOCAL_TEST_SEED` replays one).

mod common;

use arrow_array::{Array, BooleanArray, Float64Array, Int64Array, StringArray};
use common::{robocal_ok, scratch_dir, seed};
use std::path::Path;

/// One row of `FILE.params.parquet`, read with the parquet crate (not robocal's reader).
#[derive(Debug)]
struct Param {
    run: i64,
    param: String,
    estimate: f64,
    truth: f64,
    sigma: f64,
    z: f64,
    identifiable: bool,
}

fn params(path: &Path) -> Vec<Param> {
    let f = std::fs::File::open(path).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap();
    let mut out = Vec::new();
    for b in reader {
        let b = b.unwrap();
        let col = |n: &str| b.column_by_name(n).unwrap().clone();
        let (run, param) = (col("run"), col("param"));
        let run = run.as_any().downcast_ref::<Int64Array>().unwrap();
        let param = param.as_any().downcast_ref::<StringArray>().unwrap();
        let f64s = |n: &str| {
            col(n)
                .as_any()
                .downcast_ref::<Float64Array>()
                .unwrap()
                .values()
                .to_vec()
        };
        let (estimate, truth, sigma, z) =
            (f64s("estimate"), f64s("truth"), f64s("sigma"), f64s("z"));
        let ident = col("identifiable");
        let ident = ident.as_any().downcast_ref::<BooleanArray>().unwrap();
        for i in 0..b.num_rows() {
            out.push(Param {
                run: run.value(i),
                param: param.value(i).to_string(),
                estimate: estimate[i],
                truth: truth[i],
                sigma: sigma[i],
                z: z[i],
                identifiable: ident.value(i),
            });
        }
    }
    out
}

/// A column of the wide table as f64 (integers and booleans converted).
fn wide(path: &Path, name: &str) -> Vec<f64> {
    let f = std::fs::File::open(path).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap();
    let mut out = Vec::new();
    for b in reader {
        let b = b.unwrap();
        let c = b.column_by_name(name).unwrap();
        if let Some(x) = c.as_any().downcast_ref::<Float64Array>() {
            out.extend(x.values().iter().copied());
        } else if let Some(x) = c.as_any().downcast_ref::<BooleanArray>() {
            out.extend((0..x.len()).map(|i| f64::from(u8::from(x.value(i)))));
        } else {
            let x = c.as_any().downcast_ref::<Int64Array>().unwrap();
            out.extend(x.values().iter().map(|v| *v as f64));
        }
    }
    out
}

fn scenario(name: &str) -> String {
    common::repo()
        .join("scenarios")
        .join(name)
        .display()
        .to_string()
}

/// The compliance sweep (iiwa 7, the shipped elastic joints of `scenarios/iiwa7_compliance.toml`,
/// without its payloads): every identifiable stiffness parameter gets a finite z, and joint 2's
/// compliance (the best-determined: the largest gravity torque), one value per run and so
/// independent across runs, has `Σ z² ~ χ²(R)` over `R` runs if its σ describes its error. The band
/// is χ²(12)'s central 1 − 10⁻³ interval, [1.934, 34.82] (quantiles 0.0005 and 0.9995 of the
/// closed-form CDF for even degrees of freedom, `1 − e^(−x/2) Σ_{i<6} (x/2)^i / i!`, solved by
/// bisection), divided by R = 12: a false alarm in at most one seed in a thousand.
///
/// Without payloads: with them calib estimates the payload's centre of mass in an outer loop; its
/// uncertainty now enters the covariance (the compliances' mean z² went from 1.6–2.3 to 1.1–1.4 in
/// four sweeps of 100 runs, docs/sweep.md), but the excess left is not understood yet.
#[test]
fn compliance_sweep_stiffness_z_follow_chi_square() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "compliance");
    let out = dir.join("c.parquet");
    let s = seed.to_string();
    let shipped = std::fs::read_to_string(scenario("iiwa7_compliance.toml")).unwrap();
    let payload = "choice_kg = [0.0, 3.5, 7.0]";
    assert!(
        shipped.contains(payload),
        "the shipped scenario's payloads changed"
    );
    let no_payload = dir.join("iiwa7_compliance_no_payload.toml");
    std::fs::write(&no_payload, shipped.replace(payload, "choice_kg = [0.0]")).unwrap();
    robocal_ok(&[
        "sweep",
        "--scenario",
        no_payload.to_str().unwrap(),
        "--noise",
        "1",
        "--poses",
        "40",
        "--reps",
        "12",
        "--seed",
        &s,
        "--model",
        "kinematic+joint_compliance",
        "--out",
        out.to_str().unwrap(),
    ]);
    let p = params(&dir.join("c.params.parquet"));
    for x in &p {
        eprintln!("{x:?}");
    }
    let mut z2 = Vec::new();
    for run in 0..12 {
        let mine: Vec<&Param> = p.iter().filter(|x| x.run == run).collect();
        assert_eq!(mine.len(), 7, "seed {seed}: run {run} has 7 compliances");
        for x in &mine {
            assert!(
                x.truth.is_finite() && x.sigma.is_finite(),
                "seed {seed}: {x:?}"
            );
            assert_eq!(x.z.is_finite(), x.identifiable, "seed {seed}: {x:?}");
            if x.identifiable {
                assert!(
                    (x.z - (x.estimate - x.truth) / x.sigma).abs() < 1e-9 * x.z.abs().max(1.0),
                    "seed {seed}: {x:?}"
                );
            }
        }
        let j2 = mine
            .iter()
            .find(|x| x.param == "joint 2 compliance")
            .unwrap();
        assert!(j2.identifiable, "seed {seed}: {j2:?}");
        assert_eq!(j2.truth, 1.0 / 1.5e4, "the scenario's joint 2 stiffness");
        z2.push(j2.z * j2.z);
    }
    let mean = z2.iter().sum::<f64>() / z2.len() as f64;
    eprintln!("seed {seed}: mean z² of joint 2's compliance over 12 runs = {mean:.3}");
    assert!(
        (1.934 / 12.0..34.82 / 12.0).contains(&mean),
        "seed {seed}: mean z² = {mean:.3} outside χ²(12)/12's 1 − 10⁻³ interval"
    );
    // The wide table's per-cause mean agrees with the long table.
    let w = wide(&out, "param_z2_mean_joint_compliance");
    let n = wide(&out, "params_joint_compliance");
    for run in 0..12usize {
        let zs: Vec<f64> = p
            .iter()
            .filter(|x| x.run == run as i64 && x.z.is_finite())
            .map(|x| x.z * x.z)
            .collect();
        let m = zs.iter().sum::<f64>() / zs.len() as f64;
        assert!((w[run] - m).abs() < 1e-12 * m.max(1.0), "run {run}");
        assert_eq!(n[run], 7.0);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--magnitude 0,2 --magnitude-of joint_compliance` on the compliance scenario (its only effect):
/// at 0 the truth has no effect at all (nothing injected, every compliance's truth 0, and the fit
/// finds compliances within their σ of 0), at 2 the compliances are twice the scenario's (`2/k`).
/// Cells are magnitude-major: cell 0 is magnitude 0. And `--magnitude 1` writes the bytes of a
/// sweep without `--magnitude`.
#[test]
fn a_magnitude_of_zero_removes_the_effect_and_two_doubles_it() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "magnitude");
    let out = dir.join("m.parquet");
    let s = seed.to_string();
    let sc = scenario("iiwa7_compliance.toml");
    let base = [
        "sweep",
        "--scenario",
        &sc,
        "--noise",
        "1",
        "--poses",
        "40",
        "--reps",
        "2",
        "--seed",
        &s,
        "--model",
        "kinematic+joint_compliance",
    ];
    let run = |extra: &[&str], out: &Path| {
        let mut a: Vec<&str> = base.to_vec();
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out.to_str().unwrap()]);
        robocal_ok(&a);
    };
    run(
        &["--magnitude", "0,2", "--magnitude-of", "joint_compliance"],
        &out,
    );
    let magnitude = wide(&out, "magnitude");
    let cell = wide(&out, "cell");
    let injected = wide(&out, "injected_rms_m");
    assert_eq!(magnitude, [0.0, 0.0, 2.0, 2.0]);
    assert_eq!(cell, [0.0, 0.0, 1.0, 1.0]);
    assert_eq!(
        &injected[..2],
        &[0.0, 0.0],
        "seed {seed}: magnitude 0 injected something"
    );
    assert!(
        injected[2] > 1e-5 && injected[3] > 1e-5,
        "seed {seed}: {injected:?}"
    );
    let stiffness = [1.5e4, 1.5e4, 1.0e4, 1.0e4, 7.5e3, 5.0e3, 5.0e3];
    let p = params(&dir.join("m.params.parquet"));
    assert_eq!(p.len(), 4 * 7);
    for x in &p {
        let joint: usize = x.param["joint ".len()..x.param.len() - " compliance".len()]
            .parse()
            .unwrap();
        let expect = if x.run < 2 {
            0.0
        } else {
            2.0 / stiffness[joint - 1]
        };
        assert!(
            (x.truth - expect).abs() <= 1e-15 * expect,
            "seed {seed}: {x:?}, expected truth {expect:e}"
        );
        if x.identifiable {
            // |z| < 5: a false alarm of 6e-7 per parameter for a standard normal z.
            assert!(x.z.abs() < 5.0, "seed {seed}: {x:?}");
        }
    }
    // Magnitude 1 is the scenario as written: the same bytes as no --magnitude.
    let one = dir.join("one.parquet");
    let none = dir.join("none.parquet");
    run(&["--magnitude", "1"], &one);
    run(&[], &none);
    assert_eq!(std::fs::read(&one).unwrap(), std::fs::read(&none).unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A sweep of an extended model in three shards merges, both tables, to the bytes of a single run,
/// also when the shell glob `shard*.parquet` hands the shards' parameter tables to sweep-merge too.
#[test]
fn shards_of_an_extended_model_merge_to_the_same_bytes() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "shards");
    let s = seed.to_string();
    let sc = scenario("iiwa7_compliance.toml");
    let sweep = |extra: &[&str], out: &Path| {
        let mut a = vec![
            "sweep",
            "--scenario",
            &sc,
            "--noise",
            "0.5,1",
            "--poses",
            "40",
            "--reps",
            "2",
            "--seed",
            &s,
            "--model",
            "joint_compliance@2,3,4,5,6",
            "--magnitude",
            "0.5,1",
        ];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out.to_str().unwrap()]);
        robocal_ok(&a);
    };
    let single = dir.join("single.parquet");
    sweep(&[], &single);
    let mut given = Vec::new();
    for k in 0..3 {
        let part = dir.join(format!("shard{k}.parquet"));
        sweep(&["--shard", &format!("{k}/3")], &part);
        given.push(part.display().to_string());
        given.push(
            dir.join(format!("shard{k}.params.parquet"))
                .display()
                .to_string(),
        );
    }
    let merged = dir.join("merged.parquet");
    let mut a = vec!["sweep-merge", "--out", merged.to_str().unwrap()];
    a.extend(given.iter().rev().map(String::as_str));
    robocal_ok(&a);
    for ext in ["parquet", "params.parquet", "svg"] {
        assert_eq!(
            std::fs::read(single.with_extension(ext)).unwrap(),
            std::fs::read(merged.with_extension(ext)).unwrap(),
            "seed {seed}: merged {ext} differs from the single run's"
        );
    }
    let p = params(&single.with_extension("params.parquet"));
    assert_eq!(p.len(), 8 * 5, "8 runs, 5 compliances each");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bad `--magnitude`, `--magnitude-of` and `--model` values: one line naming the flag, exit 2, before
/// any run.
#[test]
fn bad_magnitudes_and_models_are_refused_by_flag() {
    let dir = scratch_dir("robocal_sweep_models", "bad");
    let out = dir.join("x.parquet");
    let sc = scenario("iiwa7_compliance.toml");
    let cases: [(&[&str], &str); 6] = [
        (&["--magnitude", "-1"], "--magnitude -1: item 1"),
        (&["--magnitude", "1,nan"], "--magnitude 1,nan: item 2"),
        (
            &["--magnitude", "1", "--magnitude-of", "stiffness"],
            "--magnitude-of stiffness: not an effect",
        ),
        (
            &["--magnitude", "1", "--magnitude-of", "backlash"],
            "--magnitude-of backlash: the scenario",
        ),
        (
            &["--magnitude-of", "joint_compliance"],
            "--magnitude-of: only with --magnitude",
        ),
        (&["--model", "joint_compliance@9"], "--model"),
    ];
    for (extra, expect) in cases {
        let mut a = vec![
            "sweep",
            "--scenario",
            &sc,
            "--noise",
            "1",
            "--poses",
            "40",
            "--reps",
            "1",
        ];
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args(&a)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{a:?}: {e}");
        assert!(e.contains(expect), "{a:?}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{a:?}: {e}");
        assert!(!out.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--model auto` (resolved per run on its training poses) and a learned correction run end to end:
/// the wide table says what each run fitted (`params_<cause>`, `learned`) and the parameter table has
/// exactly those parameters.
#[test]
fn auto_and_learned_models_say_what_they_fitted() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "auto");
    let s = seed.to_string();
    let sc = scenario("iiwa7_compliance.toml");
    for (model, learned) in [("auto", None), ("joint_compliance+learned:poly", Some(1.0))] {
        let out = dir.join("a.parquet");
        robocal_ok(&[
            "sweep",
            "--scenario",
            &sc,
            "--noise",
            "1",
            "--poses",
            "60",
            "--reps",
            "1",
            "--seed",
            &s,
            "--model",
            model,
            "--out",
            out.to_str().unwrap(),
        ]);
        let causes = [
            "joint_compliance",
            "gear_backlash",
            "thermal_drift",
            "transmission_error",
            "link_deflection",
        ];
        let n: f64 = causes
            .iter()
            .map(|c| wide(&out, &format!("params_{c}"))[0])
            .sum();
        let p = params(&dir.join("a.params.parquet"));
        assert_eq!(p.len() as f64, n, "seed {seed}: {model}");
        if let Some(l) = learned {
            assert_eq!(wide(&out, "learned"), [l], "seed {seed}: {model}");
            assert_eq!(n, 7.0);
        }
        let err = wide(&out, "test_error_rms_m")[0];
        assert!(err.is_finite() && err > 0.0, "seed {seed}: {model}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A string column of the wide table.
fn strings(path: &Path, name: &str) -> Vec<String> {
    let f = std::fs::File::open(path).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f)
        .unwrap()
        .build()
        .unwrap();
    let mut out = Vec::new();
    for b in reader {
        let b = b.unwrap();
        let c = b.column_by_name(name).unwrap();
        let x = c.as_any().downcast_ref::<StringArray>().unwrap();
        out.extend((0..x.len()).map(|i| x.value(i).to_string()));
    }
    out
}

/// `--score diagnose` on the backlash scenario with the backlash at magnitudes 0 and 1: `hidden` is
/// nothing at 0 and backlash at every joint at 1 (the scenario's uniform dead band), `named` is
/// diagnose's model, and `detected` / `false_alarm` agree with the two names at the level of causes:
/// named causes beyond the hidden ones are a false alarm, equal names a detection. The power table
/// beside it counts them per cell with Wilson intervals, the plot shows power curves, and an input
/// where the table would go is refused. Without `--score diagnose` the four columns are empty and
/// false and no power table is written.
#[test]
fn score_diagnose_records_hidden_and_named_causes() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "diagnose");
    let s = seed.to_string();
    let sc = scenario("iiwa7_backlash.toml");
    let out = dir.join("d.parquet");
    let args = |score: &str, out: &Path| {
        robocal_ok(&[
            "sweep",
            "--scenario",
            &sc,
            "--noise",
            "1",
            "--poses",
            "60",
            "--reps",
            "3",
            "--seed",
            &s,
            "--magnitude",
            "0,1",
            "--magnitude-of",
            "gear_backlash",
            "--score",
            score,
            "--out",
            out.to_str().unwrap(),
        ]);
    };
    args("diagnose", &out);
    let hidden = strings(&out, "hidden");
    let named = strings(&out, "named");
    let detected = wide(&out, "detected");
    let false_alarm = wide(&out, "false_alarm");
    let causes = |name: &str| -> Vec<String> {
        name.split('+')
            .filter(|w| *w != "kinematic")
            .map(|w| w.split('@').next().unwrap().to_string())
            .collect()
    };
    for r in 0..6 {
        let expect = if r < 3 {
            "kinematic"
        } else {
            "kinematic+gear_backlash"
        };
        assert_eq!(hidden[r], expect, "seed {seed}: run {r}");
        assert!(
            named[r].starts_with("kinematic"),
            "seed {seed}: run {r}: {}",
            named[r]
        );
        let (h, n) = (causes(&hidden[r]), causes(&named[r]));
        if n.iter().any(|c| !h.contains(c)) {
            assert_eq!(
                (detected[r], false_alarm[r]),
                (0.0, 1.0),
                "seed {seed}: run {r}: {n:?}"
            );
        }
        if named[r] == hidden[r] {
            assert_eq!(
                (detected[r], false_alarm[r]),
                (1.0, 0.0),
                "seed {seed}: run {r}"
            );
        }
        if h.iter().any(|c| !n.contains(c)) {
            assert_eq!(detected[r], 0.0, "seed {seed}: run {r}: {n:?}");
        }
    }
    // The power table: one row per cell (magnitudes 0 and 1, 3 runs each), its counts those of
    // the wide table, each interval end a root of Wilson's defining equation
    // (p̂ − p)² = z² p (1 − p) / n.
    let power = std::fs::read_to_string(dir.join("d.power.csv")).unwrap();
    let mut lines = power.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    // Every column numeric but `payloads`, empty without --payloads.
    let cells: Vec<Vec<f64>> = lines
        .map(|l| {
            l.split(',')
                .enumerate()
                .map(|(k, x)| {
                    if k == col("payloads") {
                        assert_eq!(x, "", "{power}");
                        f64::NAN
                    } else {
                        x.parse().unwrap()
                    }
                })
                .collect()
        })
        .collect();
    assert_eq!(cells.len(), 2, "{power}");
    let z = 1.959_963_984_540_054_f64;
    for (k, c) in cells.iter().enumerate() {
        assert_eq!(c[col("magnitude")], k as f64);
        assert_eq!(c[col("runs")], 3.0);
        let runs = 3 * k..3 * k + 3;
        let d: f64 = detected[runs.clone()].iter().sum();
        let f: f64 = false_alarm[runs].iter().sum();
        assert_eq!(c[col("detected")], d, "{power}");
        assert_eq!(c[col("false_alarms")], f, "{power}");
        for (count, lo, hi) in [
            (d, "detection_lower_95", "detection_upper_95"),
            (f, "false_alarm_lower_95", "false_alarm_upper_95"),
        ] {
            let p_hat = count / 3.0;
            for p in [c[col(lo)], c[col(hi)]] {
                let gap = (p_hat - p).powi(2) - z * z * p * (1.0 - p) / 3.0;
                assert!(
                    gap.abs() < 1e-12,
                    "{power}: {p} is no Wilson end for {count}/3"
                );
            }
            assert!(c[col(lo)] <= p_hat && p_hat <= c[col(hi)]);
        }
    }
    let svg = std::fs::read_to_string(dir.join("d.svg")).unwrap();
    assert!(
        svg.contains("detection rate"),
        "the plot shows power curves"
    );
    // An input where the power table would go is refused before any run.
    let clash = dir.join("s.power.csv");
    std::fs::copy(&sc, &clash).unwrap();
    let (code, err) = common::robocal_status(&[
        "sweep",
        "--scenario",
        clash.to_str().unwrap(),
        "--noise",
        "1",
        "--reps",
        "1",
        "--poses",
        "60",
        "--score",
        "diagnose",
        "--out",
        dir.join("s.parquet").to_str().unwrap(),
    ]);
    assert_eq!(code, Some(2));
    assert!(err.contains("would overwrite the input"), "{err}");
    assert!(!dir.join("s.parquet").exists());
    let plain = dir.join("plain.parquet");
    args("fit", &plain);
    assert!(!dir.join("plain.power.csv").exists());
    assert!(strings(&plain, "hidden").iter().all(String::is_empty));
    assert!(strings(&plain, "named").iter().all(String::is_empty));
    assert!(wide(&plain, "detected").iter().all(|d| *d == 0.0));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--payloads 0,0/3.5/7` on the compliance scenario: two cells, payload-set-major after the
/// magnitude (cell 0 carries nothing, cell 1 draws 0, 3.5 or 7 kg per pose), the `payloads` column
/// names each run's set, and the set reaches the truth: the payloads sag the elastic joints, so the
/// injected displacement grows, and they vary joint 2's torque more, so its compliance's predicted
/// σ shrinks (both medians over the runs). `--only-cell 1` reproduces that cell's runs alone, and
/// bad sets are refused naming `--payloads`.
#[test]
fn payload_sets_are_an_axis_of_the_grid() {
    let seed = seed();
    eprintln!("seed {seed}");
    let dir = scratch_dir("robocal_sweep_models", "payloads");
    let s = seed.to_string();
    let sc = scenario("iiwa7_compliance.toml");
    let args = |out: &Path, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "sweep",
            "--scenario",
            &sc,
            "--noise",
            "1",
            "--poses",
            "40",
            "--reps",
            "6",
            "--seed",
            &s,
            "--model",
            "kinematic+joint_compliance",
            "--payloads",
            "0,0/3.5/7",
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|x| x.to_string())
        .collect();
        a.extend(extra.iter().map(|x| x.to_string()));
        a
    };
    let out = dir.join("p.parquet");
    let a = args(&out, &[]);
    robocal_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let cell = wide(&out, "cell");
    let sets = strings(&out, "payloads");
    assert_eq!(cell.len(), 12);
    for (c, p) in cell.iter().zip(&sets) {
        assert_eq!(p, if *c == 0.0 { "0" } else { "0/3.5/7" }, "seed {seed}");
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        0.5 * (v[2] + v[3])
    };
    let injected = wide(&out, "injected_rms_m");
    let of_cell = |v: &[f64], k: f64| -> Vec<f64> {
        v.iter()
            .zip(&cell)
            .filter(|(_, c)| **c == k)
            .map(|(x, _)| *x)
            .collect()
    };
    let (mut bare, mut loaded) = (of_cell(&injected, 0.0), of_cell(&injected, 1.0));
    let (bare, loaded) = (median(&mut bare), median(&mut loaded));
    assert!(
        loaded > bare,
        "seed {seed}: injected RMS {loaded:e} m with payloads, {bare:e} m without"
    );
    let p = params(&dir.join("p.params.parquet"));
    let sigma_j2 = |k: f64| -> f64 {
        let mut v: Vec<f64> = p
            .iter()
            .filter(|x| x.param == "joint 2 compliance" && cell[x.run as usize] == k)
            .map(|x| x.sigma)
            .collect();
        median(&mut v)
    };
    assert!(
        sigma_j2(1.0) < sigma_j2(0.0),
        "seed {seed}: joint 2 compliance σ {:e} with payloads, {:e} without",
        sigma_j2(1.0),
        sigma_j2(0.0)
    );
    // One cell alone: the same runs, the same figures.
    let one = dir.join("one.parquet");
    let a = args(&one, &["--only-cell", "1"]);
    robocal_ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(
        wide(&one, "test_error_rms_m"),
        of_cell(&wide(&out, "test_error_rms_m"), 1.0),
        "seed {seed}"
    );
    assert_eq!(strings(&one, "payloads"), vec!["0/3.5/7"; 6]);
    for (bad, expect) in [
        ("0,0", "set 2 ('0'): repeats an earlier set"),
        ("3/3", "set 1 ('3/3'): 3 kg appears twice"),
        ("-1", "set 1 ('-1'): '-1' is not a mass"),
        ("0,7/x", "set 2 ('7/x'): 'x' is not a mass"),
        ("2000", "'2000' is not a mass in kg between 0 and 1000"),
    ] {
        let x = dir.join("x.parquet");
        let a: Vec<String> = args(&x, &[])
            .into_iter()
            .map(|v| if v == "0,0/3.5/7" { bad.to_string() } else { v })
            .collect();
        let o = assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args(&a)
            .output()
            .unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bad}: {e}");
        assert!(
            e.contains(&format!("--payloads {bad}: ")) && e.contains(expect),
            "{bad}: {e}"
        );
        assert_eq!(e.trim().lines().count(), 1, "{bad}: {e}");
        assert!(!x.exists());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A pose count too small for the fitted model's parameters is refused before any run, naming
/// `--poses` and counting the cause parameters: 16 poses leave 11 for calibration, 33 coordinates
/// for the iiwa 7's 31 kinematic combinations and 7 compliances. The kinematic model alone runs
/// there.
#[test]
fn too_few_poses_for_the_causes_parameters_are_refused() {
    let dir = scratch_dir("robocal_sweep_models", "few");
    let out = dir.join("x.parquet");
    let sc = scenario("iiwa7_compliance.toml");
    let run = |model: &str| {
        assert_cmd::Command::new(env!("CARGO_BIN_EXE_robocal"))
            .args([
                "sweep",
                "--scenario",
                &sc,
                "--noise",
                "1",
                "--poses",
                "25,16",
                "--reps",
                "1",
                "--model",
                model,
                "--out",
                out.to_str().unwrap(),
            ])
            .output()
            .unwrap()
    };
    let o = run("kinematic+joint_compliance");
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("--poses 25,16: 16 poses leave 11 for calibration")
            && e.contains("31 identifiable kinematic combinations and 7 cause parameters")
            && e.contains("at least 13 calibration poses"),
        "{e}"
    );
    assert_eq!(e.trim().lines().count(), 1, "{e}");
    assert!(!out.exists());
    let o = run("kinematic");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let _ = std::fs::remove_dir_all(&dir);
}
