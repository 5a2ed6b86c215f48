//! The learned models diagnose fits to the residual it leaves (`unexplained.learned`) are a report,
//! not a choice: without them diagnose adopts the same model with the same findings, steps and
//! trials. `robocal sweep --score diagnose` relies on it and does not fit them (they were a third of
//! a run's time).

use calib::select::diagnose::{DiagnoseOptions, diagnose};
use sim::scenario::{Overrides, Scenario};

/// 300 poses of the iiwa 7 with geometric errors, compliance at joint 4 and backlash at joint 1.
fn data() -> (sim::Model, sim::measurement_table::MeasurementTable) {
    let base = include_str!("../../scenarios/iiwa7_kinematic.toml");
    let text = format!(
        "{base}\n[effects.compliance]\nstiffness_nm_per_rad = [inf, inf, inf, 8e3, inf, inf, inf]\n\
         [effects.backlash]\ndead_band_rad = [4e-4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]\nmode = \"direction\"\n"
    );
    let sc = Scenario::parse(&text, "learned probes", std::path::Path::new(".")).unwrap();
    let res = sc
        .resolve(&Overrides {
            seed: Some(17),
            poses: Some(300),
            noise: None,
        })
        .unwrap();
    let dir = std::env::temp_dir().join(format!("robocal_learned_probes_{}", std::process::id()));
    sim::generate::generate(&res, &dir, None).unwrap();
    let table = sim::measurement_table::read(&dir.join("measurements.parquet")).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (res.model, table)
}

#[test]
fn without_the_learned_models_diagnose_adopts_the_same_model() {
    let (model, table) = data();
    let with = diagnose(&model, &table, "with", &DiagnoseOptions::default()).unwrap();
    let without = diagnose(
        &model,
        &table,
        "without",
        &DiagnoseOptions {
            learned_kinds: Vec::new(),
            ..DiagnoseOptions::default()
        },
    )
    .unwrap();
    // The default fits them, and they are reported; without them, none is.
    assert!(with.unexplained.learned.is_some());
    assert!(without.unexplained.learned.is_none());
    assert!(!with.findings.is_empty(), "the data hold causes to name");
    assert_eq!(with.model, without.model);
    let strip = |d: &calib::select::diagnose::Diagnosis| {
        let mut v = serde_json::to_value(d).unwrap();
        let o = v.as_object_mut().unwrap();
        o.remove("unexplained");
        o.remove("plots");
        v
    };
    assert_eq!(strip(&with), strip(&without));
}
