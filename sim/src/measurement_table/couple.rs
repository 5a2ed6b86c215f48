//! A measurement table of a robot with coupled joints ([`crate::coupled_joints`]): its joint columns
//! `q1 … qD` are the driven joints, in chain order; the coupled joints have none. [`couple`] turns it
//! into a table of every chain joint, the coupled ones computed from their sources, which is what
//! every tool evaluates; [`drive_columns`] turns such a table back into the file's columns.

use super::MeasurementTable;
use crate::error::{Result, SimError};
use crate::model::Model;
use std::path::Path;

/// A table may give a coupled joint's column (`q1 … qN` over the whole chain) as a check: its values
/// must agree with the coupling to within this (rad; m for prismatic joints), as repeated poses must
/// ([`super::POSE_REPEAT_TOLERANCE`]).
pub const COUPLING_TOLERANCE: f64 = 1e-3;

/// The table of every chain joint of `model` from a table `table` read from `file`:
/// * a robot without couplings: `table` as it is;
/// * `D` joint columns (`D` driven joints): the chain's joint values from the drives, each coupled
///   joint's `dir` the sign of `Σ aᵢ dirᵢ` over its sources (0 when they disagree or are unknown);
/// * `N` joint columns (every chain joint): the coupled joints' columns must agree with the coupling
///   to within [`COUPLING_TOLERANCE`]; the first row that does not is named.
///
/// Branch joint columns (`q_<name>`, [`MeasurementTable::branch`]) are not chain joints: they pass
/// through unchanged.
///
/// # Errors
/// [`SimError::Table`] for another joint count, or a coupled column that disagrees.
pub fn couple(table: MeasurementTable, model: &Model, file: &Path) -> Result<MeasurementTable> {
    let c = model.couplings();
    if c.is_empty() {
        return Ok(table);
    }
    let (n, d) = (model.nq(), c.n_drives());
    let err = |row: Option<usize>, column: Option<String>, message: String| SimError::Table {
        file: file.display().to_string(),
        row,
        line: None,
        column,
        message,
    };
    if table.n_joints == n {
        let mut q = vec![0.0; n];
        for r in 0..table.len() {
            q.copy_from_slice(table.q_row(r));
            c.apply(&mut q);
            for cj in c.list() {
                let (given, want) = (table.q_row(r)[cj.joint], q[cj.joint]);
                if (given - want).abs() > COUPLING_TOLERANCE {
                    return Err(err(
                        Some(r + 1),
                        Some(format!("q{}", cj.joint + 1)),
                        format!(
                            "{given} disagrees with the coupling of joint '{}' ({want} from its \
                             sources; tolerance {COUPLING_TOLERANCE})",
                            model.joints()[cj.joint].name
                        ),
                    ));
                }
            }
        }
        return Ok(table);
    }
    if table.n_joints != d {
        let coupled: Vec<String> = c
            .list()
            .iter()
            .map(|cj| format!("'{}'", model.joints()[cj.joint].name))
            .collect();
        return Err(err(
            None,
            None,
            format!(
                "{} joint columns, but robot '{}' has {d} driven joints (q1 … q{d}; its coupled \
                 joints {} have no column) of {n} chain joints",
                table.n_joints,
                model.name(),
                coupled.join(", ")
            ),
        ));
    }
    let rows = table.len();
    let mut q = vec![0.0; rows * n];
    for r in 0..rows {
        c.expand(table.q_row(r), &mut q[r * n..(r + 1) * n]);
    }
    let dir = table.dir.as_ref().map(|dir| {
        let mut out = vec![0i8; rows * n];
        let mut sum = vec![0.0; n];
        for r in 0..rows {
            sum.fill(0.0);
            for (k, &i) in c.drives().iter().enumerate() {
                let v = dir[r * d + k];
                out[r * n + i] = v;
                sum[i] = f64::from(v);
            }
            for cj in c.list() {
                let known = cj.sources.iter().all(|&(s, _)| sum[s] != 0.0);
                let terms: Vec<f64> = cj.sources.iter().map(|&(s, a)| a * sum[s]).collect();
                let agree = terms.iter().all(|t| *t > 0.0) || terms.iter().all(|t| *t < 0.0);
                out[r * n + cj.joint] = if known && agree {
                    terms[0].signum() as i8
                } else {
                    0
                };
            }
        }
        out
    });
    Ok(MeasurementTable {
        n_joints: n,
        q,
        dir,
        ..table
    })
}

/// [`couple`] for a table that is borrowed: `table` itself when it already has every chain joint of
/// `model` (or the robot has no couplings), else a coupled copy; `file` names it in errors.
///
/// # Errors
/// What [`couple`] refuses.
pub fn whole_chain<'t>(
    table: &'t MeasurementTable,
    model: &Model,
    file: &Path,
) -> Result<std::borrow::Cow<'t, MeasurementTable>> {
    if model.couplings().is_empty() || table.n_joints == model.nq() {
        return Ok(std::borrow::Cow::Borrowed(table));
    }
    Ok(std::borrow::Cow::Owned(couple(table.clone(), model, file)?))
}

/// The columns a file of a robot with coupled joints has: `table` (every chain joint) with only the
/// joint and direction columns of the driven joints `drives` (chain indices,
/// [`crate::coupled_joints::Couplings::drives`]); the inverse of [`couple`] for a table it made.
/// Branch joint columns pass through unchanged.
pub fn drive_columns(table: MeasurementTable, drives: &[usize]) -> MeasurementTable {
    let n = table.n_joints;
    let q = table
        .q
        .chunks_exact(n)
        .flat_map(|row| drives.iter().map(move |&i| row[i]))
        .collect();
    let dir = table.dir.as_ref().map(|d| {
        d.chunks_exact(n)
            .flat_map(|row| drives.iter().map(move |&i| row[i]))
            .collect()
    });
    MeasurementTable {
        n_joints: drives.len(),
        q,
        dir,
        ..table
    }
}
