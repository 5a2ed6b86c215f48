//! Numerical health of a solve, counted rather than hidden (MuJoCo's warnings: each kind counted, with
//! the index of its last occurrence).
//!
//! A [`Health`] holds, per [`Warning`] kind, how many times it occurred and the index of the last
//! occurrence: a residual row for non-finite values, an iteration for the solver's own warnings (see
//! [`Warning::index_name`]). The Levenberg–Marquardt solver fills one in every
//! [`crate::lm::MinimizationReport`]; a clean solve has none, and tests assert [`Health::is_clean`].
//!
//! In JSON a health record is the list of the warnings that occurred, e.g.
//! `[{"warning":"non_finite_residual","count":6,"last":1}]`; a clean one is `[]`.

use std::fmt;

/// A kind of numerical warning.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Warning {
    /// A residual was NaN or infinite (at the start or at a trial point). Index: the residual row.
    NonFiniteResidual,
    /// A Jacobian entry was NaN or infinite. Index: the residual row.
    NonFiniteJacobian,
    /// `χ²` or the normal matrix overflowed to infinity although every residual and Jacobian entry was
    /// finite. Index: the iteration.
    Overflow,
    /// The normal matrix is near-singular in the identifiable subspace: its Cholesky factorisation
    /// failed although its entries were finite, or the solution kept a singular value `σₖ` of the
    /// scaled Jacobian below [`crate::lm::NEAR_SINGULAR_MARGIN`] times the relative rank threshold
    /// `rank_rtol · σ_max` (the normal matrix then resolves that combination to a few digits only).
    /// Index: the iteration.
    NearSingularNormalMatrix,
    /// The iteration cap was reached before convergence. Index: the iteration.
    IterationLimit,
    /// No damping gave a decreasing step. Index: the iteration.
    DampingLimit,
}

impl Warning {
    /// Every kind, in the order of [`Warning::index`].
    pub const ALL: [Warning; 6] = [
        Warning::NonFiniteResidual,
        Warning::NonFiniteJacobian,
        Warning::Overflow,
        Warning::NearSingularNormalMatrix,
        Warning::IterationLimit,
        Warning::DampingLimit,
    ];

    /// Number of kinds.
    pub const COUNT: usize = Warning::ALL.len();

    /// Position of this kind in [`Warning::ALL`] (and in the arrays of a [`Health`]).
    pub fn index(self) -> usize {
        match self {
            Warning::NonFiniteResidual => 0,
            Warning::NonFiniteJacobian => 1,
            Warning::Overflow => 2,
            Warning::NearSingularNormalMatrix => 3,
            Warning::IterationLimit => 4,
            Warning::DampingLimit => 5,
        }
    }

    /// What the index of an occurrence counts: `"row"` (residual row) or `"iteration"`.
    pub fn index_name(self) -> &'static str {
        match self {
            Warning::NonFiniteResidual | Warning::NonFiniteJacobian => "row",
            Warning::Overflow
            | Warning::NearSingularNormalMatrix
            | Warning::IterationLimit
            | Warning::DampingLimit => "iteration",
        }
    }

    /// A short description, as the start of the warning's line.
    pub fn description(self) -> &'static str {
        match self {
            Warning::NonFiniteResidual => "non-finite residual",
            Warning::NonFiniteJacobian => "non-finite Jacobian entry",
            Warning::Overflow => "χ² or the normal matrix overflowed",
            Warning::NearSingularNormalMatrix => "near-singular normal matrix",
            Warning::IterationLimit => "iteration limit reached",
            Warning::DampingLimit => "damping limit reached (no decreasing step)",
        }
    }
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.description())
    }
}

/// One kind of warning that occurred: how often, and where last (the entry of [`Health::iter`] and of
/// its JSON list).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WarningCount {
    /// The kind.
    pub warning: Warning,
    /// Number of occurrences (at least 1).
    pub count: usize,
    /// Index of the last occurrence: a residual row or an iteration ([`Warning::index_name`]).
    pub last: usize,
}

impl fmt::Display for WarningCount {
    /// One line, e.g. `non-finite residual: 6 times, last at row 1`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let times = if self.count == 1 { "time" } else { "times" };
        write!(
            f,
            "{}: {} {times}, last at {} {}",
            self.warning,
            self.count,
            self.warning.index_name(),
            self.last
        )
    }
}

/// Numerical warnings of a solve (or of several, merged): per [`Warning`] kind the number of
/// occurrences and the index of the last one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(from = "Vec<WarningCount>", into = "Vec<WarningCount>")]
pub struct Health {
    /// Occurrences per kind, indexed by [`Warning::index`].
    counts: [usize; Warning::COUNT],
    /// Index of the last occurrence per kind (meaningful where the count is non-zero).
    last: [usize; Warning::COUNT],
}

impl Health {
    /// A clean record (no warning).
    pub fn new() -> Self {
        Health::default()
    }

    /// Counts one occurrence of `warning` at `index` (a residual row or an iteration, see
    /// [`Warning::index_name`]).
    pub fn record(&mut self, warning: Warning, index: usize) {
        let k = warning.index();
        self.counts[k] += 1;
        self.last[k] = index;
    }

    /// True when no warning occurred.
    pub fn is_clean(&self) -> bool {
        self.counts.iter().all(|c| *c == 0)
    }

    /// Number of occurrences of `warning`.
    pub fn count(&self, warning: Warning) -> usize {
        self.counts[warning.index()]
    }

    /// Index of the last occurrence of `warning`, `None` if it never occurred.
    pub fn last(&self, warning: Warning) -> Option<usize> {
        let k = warning.index();
        (self.counts[k] > 0).then_some(self.last[k])
    }

    /// Total number of occurrences over all kinds.
    pub fn total(&self) -> usize {
        self.counts.iter().sum()
    }

    /// Adds the warnings of `other`, taken as the later record: counts add, and the last index of a
    /// kind is `other`'s wherever `other` has that kind. (Row indices refer to each solve's own rows.)
    pub fn merge(&mut self, other: &Health) {
        for k in 0..Warning::COUNT {
            if other.counts[k] > 0 {
                self.counts[k] += other.counts[k];
                self.last[k] = other.last[k];
            }
        }
    }

    /// The warnings that occurred, in the order of [`Warning::ALL`].
    pub fn iter(&self) -> impl Iterator<Item = WarningCount> + '_ {
        Warning::ALL.iter().filter_map(|&w| {
            let k = w.index();
            (self.counts[k] > 0).then_some(WarningCount {
                warning: w,
                count: self.counts[k],
                last: self.last[k],
            })
        })
    }
}

impl fmt::Display for Health {
    /// One line per warning that occurred (see [`WarningCount`]'s `Display`), or
    /// `no numerical warnings`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_clean() {
            return f.write_str("no numerical warnings");
        }
        for (i, w) in self.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "{w}")?;
        }
        Ok(())
    }
}

impl From<Health> for Vec<WarningCount> {
    fn from(h: Health) -> Self {
        h.iter().collect()
    }
}

impl From<Vec<WarningCount>> for Health {
    /// Entries in list order, merged (a kind listed twice adds up; the later entry gives the last
    /// index). Entries with a zero count are ignored.
    fn from(list: Vec<WarningCount>) -> Self {
        let mut h = Health::new();
        for w in list.iter().filter(|w| w.count > 0) {
            let k = w.warning.index();
            h.counts[k] += w.count;
            h.last[k] = w.last;
        }
        h
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_is_in_index_order() {
        for (k, w) in Warning::ALL.iter().enumerate() {
            assert_eq!(w.index(), k);
        }
    }

    #[test]
    fn record_count_last_and_merge() {
        let mut a = Health::new();
        assert!(a.is_clean());
        assert_eq!(a.to_string(), "no numerical warnings");
        a.record(Warning::NonFiniteResidual, 4);
        a.record(Warning::NonFiniteResidual, 2);
        a.record(Warning::IterationLimit, 100);
        assert!(!a.is_clean());
        assert_eq!(a.count(Warning::NonFiniteResidual), 2);
        assert_eq!(a.last(Warning::NonFiniteResidual), Some(2));
        assert_eq!(a.last(Warning::DampingLimit), None);
        assert_eq!(a.total(), 3);

        let mut b = Health::new();
        b.record(Warning::NonFiniteResidual, 7);
        b.record(Warning::DampingLimit, 3);
        let mut m = a;
        m.merge(&b);
        assert_eq!(m.count(Warning::NonFiniteResidual), 3);
        assert_eq!(m.last(Warning::NonFiniteResidual), Some(7));
        assert_eq!(m.last(Warning::IterationLimit), Some(100));
        assert_eq!(m.last(Warning::DampingLimit), Some(3));
        let mut clean = Health::new();
        clean.merge(&Health::new());
        assert!(clean.is_clean());
        assert_eq!(
            m.to_string(),
            "non-finite residual: 3 times, last at row 7\n\
             iteration limit reached: 1 time, last at iteration 100\n\
             damping limit reached (no decreasing step): 1 time, last at iteration 3"
        );
    }

    #[test]
    fn json_is_the_list_of_warnings_and_round_trips() {
        assert_eq!(serde_json::to_string(&Health::new()).unwrap(), "[]");
        let mut h = Health::new();
        h.record(Warning::NearSingularNormalMatrix, 5);
        h.record(Warning::NonFiniteJacobian, 9);
        let s = serde_json::to_string(&h).unwrap();
        assert_eq!(
            s,
            r#"[{"warning":"non_finite_jacobian","count":1,"last":9},{"warning":"near_singular_normal_matrix","count":1,"last":5}]"#
        );
        let back: Health = serde_json::from_str(&s).unwrap();
        assert_eq!(back, h);
    }
}
