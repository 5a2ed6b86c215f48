//! The values of a robot's branch joints ([`crate::branches`]) from a measurement table's
//! `q_<joint name>` columns ([`super::BranchColumns`]), in the model's order: what the statics of
//! both the simulator and the estimator read per row ([`crate::Data::pose_branches`]). A branch joint
//! without a column is at zero; a column that names no branch joint is not read
//! ([`super::ModelCheck`] warns about both).

use super::MeasurementTable;
use crate::model::Model;

/// Where each of a model's branch joints is among a table's branch columns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BranchValues {
    /// Per branch joint of the model ([`crate::branches::Branches::joints`] order): its column
    /// among the table's branch columns, or `None` (at zero).
    at: Vec<Option<usize>>,
    /// Branch columns per table row.
    width: usize,
}

impl BranchValues {
    /// The map from `table`'s branch columns to `model`'s branch joints; `None` when no column of
    /// the table names a branch joint of the model (the branches are at zero on every row).
    pub fn new(table: &MeasurementTable, model: &Model) -> Option<BranchValues> {
        let names = table.branch_names();
        let at: Vec<Option<usize>> = model
            .branches()
            .joints()
            .iter()
            .map(|j| names.iter().position(|n| *n == j.name))
            .collect();
        at.iter().any(Option::is_some).then_some(BranchValues {
            at,
            width: names.len(),
        })
    }

    /// Number of branch joints of the model (the length of a row's values).
    pub fn len(&self) -> usize {
        self.at.len()
    }

    /// True when the model has no branch joint (never, for a map [`BranchValues::new`] made).
    pub fn is_empty(&self) -> bool {
        self.at.is_empty()
    }

    /// Row `r`'s branch joint values (rad or m, the model's order) into `out` (one per branch
    /// joint), zero for a joint without a column; returns `out`. Does not allocate.
    ///
    /// # Panics
    /// If `table` is not the one the map was made for, or `out` has the wrong length.
    pub fn row<'o>(&self, table: &MeasurementTable, r: usize, out: &'o mut [f64]) -> &'o [f64] {
        assert_eq!(out.len(), self.at.len(), "one value per branch joint");
        let values = table.branch_row(r).expect("a table with branch columns");
        debug_assert_eq!(values.len(), self.width);
        for (o, at) in out.iter_mut().zip(&self.at) {
            *o = at.map_or(0.0, |k| values[k]);
        }
        out
    }
}
