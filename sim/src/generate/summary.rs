//! The summary statistics of a generation ([`super::Summary`]), accumulated row by row as the rows
//! stream past, in row order, so that every sum is the same floating-point sum whatever the chunk
//! sizes; and the exact median of the target distances in bounded memory ([`MedianSelector`]).

use super::simulate::Simulation;
use crate::effects::{Contributions, EffectId};
use crate::scenario::{Resolved, TruthModel};

/// Length of `v` (m): the one formula of every length in the summary, and of the target distance
/// the median is taken of (read back from `truth.parquet`, it must give the same bits).
pub(super) fn distance(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Sum of squares and largest value of one displacement length over the rows (m², m).
#[derive(Clone, Copy, Debug, Default)]
struct SizeSum {
    s2: f64,
    max: f64,
}

impl SizeSum {
    fn add(&mut self, l: f64) {
        self.s2 += l * l;
        self.max = self.max.max(l);
    }
    fn size(&self, effect: &'static str, n: f64) -> EffectSize {
        EffectSize {
            effect,
            rms_m: (self.s2 / n).sqrt(),
            max_m: self.max,
        }
    }
}

/// The running sums of [`super::Summary`]: RMS and largest displacement of each injected effect and of
/// their total, RMS of the noise over rows without an outlier, outliers, compliance steps, and the
/// target distances for the median.
#[derive(Debug)]
pub(super) struct Accumulator {
    effects: Vec<(EffectId, SizeSum)>,
    total: SizeSum,
    noise_s2: f64,
    noise_rows: usize,
    outliers: usize,
    steps_sum: f64,
    steps_max: f64,
    rows: usize,
    pub(super) median: MedianSelector,
}

/// What [`Accumulator::finish`] gives.
pub(super) struct Totals {
    pub(super) effects: Vec<EffectSize>,
    pub(super) total_rms_m: f64,
    pub(super) noise_rms_m: f64,
    pub(super) outliers: usize,
    pub(super) steps_mean_max: [f64; 2],
}

impl Accumulator {
    /// Sums for the injected effects `ids` over `rows` rows; the median is kept in memory up to
    /// `in_memory_rows` rows ([`MedianSelector::new`]).
    pub(super) fn new(ids: Vec<EffectId>, rows: usize, in_memory_rows: usize) -> Accumulator {
        Accumulator {
            effects: ids.into_iter().map(|id| (id, SizeSum::default())).collect(),
            total: SizeSum::default(),
            noise_s2: 0.0,
            noise_rows: 0,
            outliers: 0,
            steps_sum: 0.0,
            steps_max: 0.0,
            rows: 0,
            median: MedianSelector::new(rows, in_memory_rows),
        }
    }

    /// Adds the rows of `sim`, which must follow those added before.
    pub(super) fn add(&mut self, sim: &Simulation) {
        for r in &sim.rows {
            let c: &Contributions = &r.contribution;
            for (id, s) in &mut self.effects {
                s.add(distance(c.get(*id)));
            }
            self.total.add(distance(c.total()));
            if r.reading.outlier {
                self.outliers += 1;
            } else {
                let l = distance(r.reading.noise);
                self.noise_s2 += l * l;
                self.noise_rows += 1;
            }
            let steps = r.compliance_iterations as f64;
            self.steps_sum += steps;
            self.steps_max = self.steps_max.max(steps);
            self.median.add(distance(r.reading.p_true));
        }
        self.rows += sim.rows.len();
    }

    /// The statistics over every row added.
    pub(super) fn finish(&self) -> Totals {
        let n = self.rows.max(1) as f64;
        Totals {
            effects: self
                .effects
                .iter()
                .map(|(id, s)| s.size(id.name(), n))
                .collect(),
            total_rms_m: self.total.size("total", n).rms_m,
            noise_rms_m: if self.noise_rows > 0 {
                (self.noise_s2 / self.noise_rows as f64).sqrt()
            } else {
                0.0
            },
            outliers: self.outliers,
            steps_mean_max: [self.steps_sum / n, self.steps_max],
        }
    }
}

/// The order key of `x`: keys compare as [`f64::total_cmp`] orders the values.
fn key(x: f64) -> u64 {
    let b = x.to_bits();
    if b >> 63 == 1 { !b } else { b | 1 << 63 }
}

/// The value of an order [`key`].
fn value(k: u64) -> f64 {
    f64::from_bits(if k >> 63 == 1 { k & !(1 << 63) } else { !k })
}

/// Bits of the key a histogram level resolves.
const LEVEL_BITS: u32 = 16;

/// Values a selection pass collects to sort, at most (8 MB).
pub(super) const COLLECT_LIMIT: usize = 1 << 20;

/// The exact element of rank `⌊n/2⌋` (0-based, in [`f64::total_cmp`] order) of `n` values seen once
/// in a stream, in bounded memory: what `sort` then `v[n / 2]` gives. Up to `in_memory_rows` values
/// are kept and selected directly. Beyond, a radix selection: a histogram of the top 16 bits of each
/// value's order key is counted as the values pass, which places the answer in one bucket; then
/// further passes over the values, read again ([`MedianSelector::select`]), either histogram the next
/// 16 bits of the keys in that bucket or, once it holds at most [`COLLECT_LIMIT`] values, collect and
/// select them. At most four passes; memory 512 kB plus the collected values.
#[derive(Debug)]
pub(super) enum MedianSelector {
    /// Every value.
    InMemory(Vec<f64>),
    /// The first-level histogram.
    Radix { histogram: Vec<u64>, n: u64 },
}

impl MedianSelector {
    /// A selector for `n` values, kept in memory when `n ≤ in_memory_rows`.
    pub(super) fn new(n: usize, in_memory_rows: usize) -> MedianSelector {
        if n <= in_memory_rows {
            MedianSelector::InMemory(Vec::with_capacity(n))
        } else {
            MedianSelector::Radix {
                histogram: vec![0; 1 << LEVEL_BITS],
                n: 0,
            }
        }
    }

    /// Counts value `x`.
    pub(super) fn add(&mut self, x: f64) {
        match self {
            MedianSelector::InMemory(v) => v.push(x),
            MedianSelector::Radix { histogram, n } => {
                histogram[(key(x) >> (64 - LEVEL_BITS)) as usize] += 1;
                *n += 1;
            }
        }
    }

    /// The median (0 without values). `replay` calls its argument once with every value again, in
    /// any order (only for the radix selection).
    ///
    /// # Errors
    /// What `replay` reports.
    pub(super) fn select<E>(
        self,
        mut replay: impl FnMut(&mut dyn FnMut(f64)) -> Result<(), E>,
    ) -> Result<f64, E> {
        let (histogram, n) = match self {
            MedianSelector::InMemory(mut v) => {
                if v.is_empty() {
                    return Ok(0.0);
                }
                let k = v.len() / 2;
                let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
                return Ok(*m);
            }
            MedianSelector::Radix { histogram, n } => (histogram, n),
        };
        if n == 0 {
            return Ok(0.0);
        }
        // The bucket holding the answer: its key prefix, prefix length, the answer's rank among the
        // bucket's values, and their number.
        let (mut prefix, mut count, mut rank) = bucket_of(&histogram, n / 2);
        let mut bits = LEVEL_BITS;
        loop {
            if bits == 64 {
                return Ok(value(prefix));
            }
            let shift = 64 - bits;
            if count <= COLLECT_LIMIT as u64 {
                let mut keys = Vec::with_capacity(count as usize);
                replay(&mut |x| {
                    let k = key(x);
                    if k >> shift == prefix {
                        keys.push(k);
                    }
                })?;
                let (_, m, _) = keys.select_nth_unstable(rank as usize);
                return Ok(value(*m));
            }
            let mut next = vec![0u64; 1 << LEVEL_BITS];
            let sub = shift - LEVEL_BITS;
            let mask = (1u64 << LEVEL_BITS) - 1;
            replay(&mut |x| {
                let k = key(x);
                if k >> shift == prefix {
                    next[((k >> sub) & mask) as usize] += 1;
                }
            })?;
            let (b, c, r) = bucket_of(&next, rank);
            prefix = (prefix << LEVEL_BITS) | b;
            count = c;
            rank = r;
            bits += LEVEL_BITS;
        }
    }
}

/// The bucket of `histogram` holding the element of rank `rank`: its index, its count, and the rank
/// within it.
fn bucket_of(histogram: &[u64], rank: u64) -> (u64, u64, u64) {
    let mut below = 0;
    for (b, &c) in histogram.iter().enumerate() {
        if rank < below + c {
            return (b as u64, c, rank - below);
        }
        below += c;
    }
    unreachable!("the rank is below the total count")
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The median as the generator computed it before streaming: sort, then the middle element.
    fn sorted_median(v: &[f64]) -> f64 {
        let mut d = v.to_vec();
        d.sort_unstable_by(f64::total_cmp);
        if d.is_empty() { 0.0 } else { d[d.len() / 2] }
    }

    fn radix_median(v: &[f64]) -> (f64, usize) {
        let mut s = MedianSelector::new(v.len(), 0);
        for &x in v {
            s.add(x);
        }
        let mut passes = 0;
        let m = s
            .select(|f: &mut dyn FnMut(f64)| {
                passes += 1;
                v.iter().rev().for_each(|&x| f(x));
                Ok::<(), ()>(())
            })
            .unwrap();
        (m, passes)
    }

    #[test]
    fn keys_order_as_total_cmp_and_invert() {
        let xs = [
            f64::NEG_INFINITY,
            -1e300,
            -1.0,
            -f64::MIN_POSITIVE,
            -0.0,
            0.0,
            5e-324,
            1.0,
            2.5,
            f64::INFINITY,
        ];
        for w in xs.windows(2) {
            assert!(key(w[0]) < key(w[1]), "{} {}", w[0], w[1]);
        }
        for x in xs {
            assert_eq!(value(key(x)).to_bits(), x.to_bits());
        }
    }

    #[test]
    fn the_radix_selection_finds_what_sorting_finds() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(12);
        // Target distances like a campaign's, values that tie, a single value, two values, and one
        // value repeated more often than a pass collects (every level down to the full key).
        let distances: Vec<f64> = (0..50_001)
            .map(|_| 2.0 + rng.random::<f64>() * 1.5)
            .collect();
        let ties: Vec<f64> = (0..10_000)
            .map(|_| f64::from(rng.random_range(0..5u8)))
            .collect();
        let same = vec![2.75; COLLECT_LIMIT + 3];
        let mixed: Vec<f64> = (0..COLLECT_LIMIT + 10)
            .map(|i| {
                if i % 1000 == 0 {
                    rng.random::<f64>()
                } else {
                    2.75 + f64::from((i % 3) as u8) * 1e-15
                }
            })
            .collect();
        for (name, v) in [
            ("distances", distances),
            ("ties", ties),
            ("one", vec![3.0]),
            ("two", vec![3.0, 1.0]),
            ("same", same),
            ("mixed", mixed),
        ] {
            let (m, passes) = radix_median(&v);
            assert_eq!(m.to_bits(), sorted_median(&v).to_bits(), "{name}");
            assert!(passes <= 4, "{name}: {passes} passes");
            // In memory: the same.
            let mut s = MedianSelector::new(v.len(), usize::MAX);
            v.iter().for_each(|&x| s.add(x));
            let m = s
                .select(|_: &mut dyn FnMut(f64)| -> Result<(), ()> { panic!("no replay") })
                .unwrap();
            assert_eq!(m.to_bits(), sorted_median(&v).to_bits(), "{name}");
        }
    }
}

/// Root-mean-square displacement (m) and largest one of one effect over the rows.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EffectSize {
    /// Effect name ([`EffectId::name`]: `thermal_drift`, `kinematic_offsets`, `gear_backlash`,
    /// `joint_compliance`).
    pub effect: &'static str,
    /// RMS of the displacement length over the rows (m).
    pub rms_m: f64,
    /// Largest displacement length (m).
    pub max_m: f64,
}

/// What a generation produced, for the summary paragraph and `truth.json`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Robot name.
    pub robot: String,
    /// How the truth was computed (`analytic` or `rapier`).
    pub truth_model: TruthModel,
    /// Compliance solve per row: mean and largest Newton iterations (analytic) or engine steps
    /// (rapier); zeros without compliance.
    pub compliance_steps_mean_max: [f64; 2],
    /// Seed in force.
    pub seed: u64,
    /// Poses.
    pub poses: usize,
    /// Rows (measurements).
    pub rows: usize,
    /// The injected effects and their sizes at the target.
    pub effects: Vec<EffectSize>,
    /// RMS of the total deviation of the real target from the nominal one (m).
    pub total_rms_m: f64,
    /// Noise multiplier.
    pub noise_scale: f64,
    /// Median target distance from the tracker (m).
    pub median_distance_m: f64,
    /// Radial and transverse σ at the median distance (m, scaled).
    pub sigma_at_median_m: [f64; 2],
    /// RMS length of the added noise vector over rows without outliers (m).
    pub noise_rms_m: f64,
    /// Rows with a gross outlier.
    pub outliers: usize,
    /// Files written (paths as given; not stored in `truth.json`, which must not depend on the output
    /// folder).
    #[serde(skip)]
    pub files: Vec<String>,
}

fn fmt_len(m: f64) -> String {
    if m == 0.0 {
        "0".into()
    } else if m < 1e-3 {
        format!("{:.1} µm", m * 1e6)
    } else {
        format!("{:.3} mm", m * 1e3)
    }
}

impl Summary {
    /// One human-readable paragraph.
    pub fn paragraph(&self) -> String {
        let effects = if self.effects.is_empty() {
            "no injected effects".to_string()
        } else {
            let parts: Vec<String> = self
                .effects
                .iter()
                .map(|e| {
                    format!(
                        "{} (RMS {}, max {})",
                        e.effect,
                        fmt_len(e.rms_m),
                        fmt_len(e.max_m)
                    )
                })
                .collect();
            format!(
                "effects {}; total RMS deviation {}",
                parts.join(", "),
                fmt_len(self.total_rms_m)
            )
        };
        let noise = if self.noise_scale == 0.0 {
            "noise-free (scale 0)".to_string()
        } else {
            format!(
                "tracker noise ×{}: σ_radial {}, σ_transverse {} at the median distance {:.2} m, RMS |noise| {}, {} outlier row(s)",
                self.noise_scale,
                fmt_len(self.sigma_at_median_m[0]),
                fmt_len(self.sigma_at_median_m[1]),
                self.median_distance_m,
                fmt_len(self.noise_rms_m),
                self.outliers
            )
        };
        let truth = match self.truth_model {
            TruthModel::Analytic => String::new(),
            TruthModel::Rapier => format!(
                " (rapier physics-engine compliance, {:.1} steps per pose on average)",
                self.compliance_steps_mean_max[0]
            ),
        };
        format!(
            "generated {} poses ({} measurements) of robot '{}'{truth}, seed {}; {}; {}; wrote {}.",
            self.poses,
            self.rows,
            self.robot,
            self.seed,
            effects,
            noise,
            self.files.join(", ")
        )
    }
}

/// The summary of a campaign of `poses` poses and `rows` rows from its accumulated statistics and the
/// median target distance (m).
pub(super) fn summarize(
    res: &Resolved,
    (poses, rows): (usize, usize),
    totals: Totals,
    median: f64,
    files: Vec<String>,
) -> Summary {
    let (sr, st) = res.tracker.sigmas(median);
    Summary {
        robot: res.model.name().to_string(),
        truth_model: res.truth_model,
        compliance_steps_mean_max: totals.steps_mean_max,
        seed: res.seed,
        poses,
        rows,
        effects: totals.effects,
        total_rms_m: totals.total_rms_m,
        noise_scale: res.tracker.noise_scale(),
        median_distance_m: median,
        sigma_at_median_m: [sr, st],
        noise_rms_m: totals.noise_rms_m,
        outliers: totals.outliers,
        files,
    }
}
