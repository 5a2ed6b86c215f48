//! Where a learned correction has seen data: its **support** in joint space.
//!
//! A learned correction is a function of the joint angles fitted to the residuals of its training
//! poses. Between those poses it interpolates; away from them it extrapolates, and on real robots that
//! loses: the UR10 correction learned on series A (poses near one flange orientation) makes series B
//! worse than no correction at all. So a correction is applied only where it has data:
//!
//! - The metric is the Euclidean distance between joint vectors, `d(q, q') = |q − q'|` (rad; m for a
//!   prismatic joint), in the coordinates the correction is a function of.
//! - The **scale** `h` is the 90th percentile of the training poses' nearest-neighbour distances (for a
//!   seeded sample of at most [`SCALE_SAMPLE`] poses, each against all others): how far apart the
//!   training poses lie where they are densest.
//! - The training poses are **covered** by centres: in a seeded order, a pose becomes a centre when no
//!   centre lies within `r_c = h` of it (at most [`MAX_CENTRES`]: `r_c` doubles until they fit). Every
//!   training pose is then within `r_c` of a centre, and the file stores the centres, not the poses.
//! - With `d_c(q)` the distance to the nearest centre, the correction's **weight** is 1 for
//!   `d_c ≤ r_in = r_c + INNER · h`, 0 for `d_c ≥ r_out = r_in + FADE · h`, and a smoothstep
//!   `1 − 3t² + 2t³` (`t = (d_c − r_in)/(r_out − r_in)`) between: a pose within `INNER · h` of a
//!   training pose gets the whole correction, and one further than `r_c + (INNER + FADE) · h` from
//!   every training pose gets none.
//!
//! On the UR10 (README): series A's scale is 0.15 rad, and series B's poses lie 0.9 to 1.9 rad from
//! the nearest pose of A, so the correction learned on A is off on all of B; held-out poses of A lie
//! within it.

use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Most poses whose nearest-neighbour distance estimates the scale `h`.
pub const SCALE_SAMPLE: usize = 2000;
/// Most centres a support keeps.
pub const MAX_CENTRES: usize = 4000;
/// The correction is whole within `INNER · h` of a training pose (beyond the covering radius).
pub const INNER: f64 = 2.0;
/// ... and fades to zero over a further `FADE · h`.
pub const FADE: f64 = 2.0;

/// The support of a learned correction: centres covering its training poses and the radii of its fade.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Support {
    /// Joints per configuration.
    pub n_joints: usize,
    /// Centre configurations, row-major (centres × joints; rad).
    pub centres: Vec<f64>,
    /// Distinct training configurations covered.
    pub n_training: usize,
    /// Nearest-neighbour scale `h` of the training configurations (rad).
    pub scale_rad: f64,
    /// Covering radius `r_c`: every training configuration is within it of a centre (rad).
    pub cover_rad: f64,
    /// Radius (to the nearest centre) within which the correction is whole (rad).
    pub inner_rad: f64,
    /// Radius beyond which the correction is off (rad).
    pub outer_rad: f64,
}

/// Squared distance between two configurations.
fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

impl Support {
    /// The support of the training configurations `q` (row-major, `n_joints` per row; repeats and
    /// rows of the same pose count once), sampled and ordered with `seed`. `None` without a
    /// configuration or with non-finite values.
    pub fn of(q: &[f64], n_joints: usize, seed: u64) -> Option<Support> {
        if n_joints == 0
            || q.is_empty()
            || !q.len().is_multiple_of(n_joints)
            || q.iter().any(|v| !v.is_finite())
        {
            return None;
        }
        // Distinct configurations, in the order of first appearance.
        let mut seen = std::collections::HashSet::new();
        let mut points: Vec<&[f64]> = Vec::new();
        for row in q.chunks(n_joints) {
            let key: Vec<u64> = row.iter().map(|v| v.to_bits()).collect();
            if seen.insert(key) {
                points.push(row);
            }
        }
        let n = points.len();
        let mut rng = StdRng::seed_from_u64(seed ^ 0x0073_7570_706f_7274);
        let mut order: Vec<usize> = (0..n).collect();
        order.shuffle(&mut rng);
        // The scale: nearest-neighbour distances of a sample against every other configuration.
        let sample = &order[..n.min(SCALE_SAMPLE)];
        let mut nn: Vec<f64> = sample
            .par_iter()
            .map(|&i| {
                points
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, p)| dist2(points[i], p))
                    .fold(f64::INFINITY, f64::min)
                    .sqrt()
            })
            .collect();
        nn.retain(|d| d.is_finite());
        nn.sort_by(f64::total_cmp);
        // A single configuration (or identical ones): a scale of 1 mrad, the support a point.
        let scale = match nn.len() {
            0 => 1e-3,
            k => nn[((k - 1) as f64 * 0.9).round() as usize].max(1e-6),
        };
        let mut cover = scale;
        let centres = loop {
            let mut centres: Vec<f64> = Vec::new();
            let mut fits = true;
            for &i in &order {
                let p = points[i];
                let covered = centres
                    .chunks(n_joints)
                    .any(|c| dist2(c, p) <= cover * cover);
                if !covered {
                    if centres.len() / n_joints == MAX_CENTRES {
                        fits = false;
                        break;
                    }
                    centres.extend_from_slice(p);
                }
            }
            if fits {
                break centres;
            }
            cover *= 2.0;
        };
        let inner = cover + INNER * scale;
        Some(Support {
            n_joints,
            centres,
            n_training: n,
            scale_rad: scale,
            cover_rad: cover,
            inner_rad: inner,
            outer_rad: inner + FADE * scale,
        })
    }

    /// Distance from `q` to the nearest centre (rad); infinite for a `q` of the wrong length.
    pub fn distance(&self, q: &[f64]) -> f64 {
        if q.len() != self.n_joints {
            return f64::INFINITY;
        }
        self.centres
            .chunks(self.n_joints)
            .map(|c| dist2(c, q))
            .fold(f64::INFINITY, f64::min)
            .sqrt()
    }

    /// Weight of the correction at `q`: 1 inside, 0 outside, a smoothstep across the edge.
    pub fn weight(&self, q: &[f64]) -> f64 {
        let d = self.distance(q);
        if d <= self.inner_rad {
            1.0
        } else if d >= self.outer_rad || !d.is_finite() {
            0.0
        } else {
            let t = (d - self.inner_rad) / (self.outer_rad - self.inner_rad);
            1.0 - t * t * (3.0 - 2.0 * t)
        }
    }

    /// The weight at `q` ([`Support::weight`]), with its gradient `∂w/∂q` (1/rad) into `out` (one
    /// per joint) from the same search for the nearest centre: zero inside and outside, the
    /// smoothstep's slope along the direction away from the nearest centre across the edge. A `q` or
    /// `out` of the wrong length gives weight 0 and a zero gradient, as [`Support::weight`] does.
    pub fn weight_and_gradient(&self, q: &[f64], out: &mut [f64]) -> f64 {
        out.fill(0.0);
        if q.len() != self.n_joints || out.len() != self.n_joints {
            return 0.0;
        }
        let Some(centre) = self
            .centres
            .chunks(self.n_joints)
            .min_by(|a, b| dist2(a, q).total_cmp(&dist2(b, q)))
        else {
            return 0.0;
        };
        let d = dist2(centre, q).sqrt();
        if d <= self.inner_rad {
            return 1.0;
        }
        if d >= self.outer_rad {
            return 0.0;
        }
        let width = self.outer_rad - self.inner_rad;
        let t = (d - self.inner_rad) / width;
        let dw_dd = (6.0 * t * t - 6.0 * t) / width;
        for ((o, qi), ci) in out.iter_mut().zip(q).zip(centre) {
            *o = dw_dd * (qi - ci) / d;
        }
        1.0 - t * t * (3.0 - 2.0 * t)
    }

    /// Number of centres.
    pub fn n_centres(&self) -> usize {
        self.centres.len() / self.n_joints
    }

    /// Checks a support read from a file: lengths, finite non-negative radii in order.
    pub fn check(&self) -> std::result::Result<(), String> {
        if self.n_joints == 0 || !self.centres.len().is_multiple_of(self.n_joints) {
            return Err(format!(
                "key 'learned.support.centres' has {} values, not a multiple of {} joints",
                self.centres.len(),
                self.n_joints
            ));
        }
        if let Some(v) = self.centres.iter().find(|v| !v.is_finite()) {
            return Err(format!(
                "key 'learned.support.centres' holds {v}: not finite"
            ));
        }
        let radii = [
            ("scale_rad", self.scale_rad),
            ("cover_rad", self.cover_rad),
            ("inner_rad", self.inner_rad),
            ("outer_rad", self.outer_rad),
        ];
        for (name, v) in radii {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!(
                    "key 'learned.support.{name}' is {v}: a radius is finite and ≥ 0"
                ));
            }
        }
        if self.outer_rad <= self.inner_rad {
            return Err(format!(
                "key 'learned.support.outer_rad' ({}) is not beyond 'inner_rad' ({})",
                self.outer_rad, self.inner_rad
            ));
        }
        Ok(())
    }

    /// One line for people.
    pub fn describe(&self) -> String {
        format!(
            "applied within {:.3} rad of its {} training configurations ({} centres, nearest-neighbour \
             scale {:.3} rad), faded out by {:.3} rad",
            self.inner_rad - self.cover_rad,
            self.n_training,
            self.n_centres(),
            self.scale_rad,
            self.outer_rad
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of 1-D configurations 0.1 rad apart: the scale is 0.1, every configuration is inside,
    /// and the weight falls by a smoothstep from `r_in` to `r_out` (hand values).
    #[test]
    fn grid_scale_weight_and_fade() {
        let q: Vec<f64> = (0..21).map(|i| i as f64 * 0.1).collect();
        let s = Support::of(&q, 1, 3).unwrap();
        assert!((s.scale_rad - 0.1).abs() < 1e-12, "{}", s.scale_rad);
        assert_eq!(s.n_training, 21);
        for &v in &q {
            assert_eq!(s.weight(&[v]), 1.0);
        }
        // Every training configuration within cover of a centre.
        for &v in &q {
            assert!(s.distance(&[v]) <= s.cover_rad + 1e-12);
        }
        // Beyond the last configuration (2.0): distance to the nearest centre ≥ the distance to 2.0.
        let far = 2.0 + s.outer_rad + 1e-9;
        assert_eq!(s.weight(&[far]), 0.0);
        assert_eq!(s.weight(&[-s.outer_rad - 1e-9]), 0.0);
        // Halfway across the fade from a centre at 0: weight 1/2 by symmetry of the smoothstep.
        let mid = -(s.inner_rad + s.outer_rad) / 2.0;
        let d0 = s.distance(&[mid]);
        let t = (d0 - s.inner_rad) / (s.outer_rad - s.inner_rad);
        assert!((s.weight(&[mid]) - (1.0 - t * t * (3.0 - 2.0 * t))).abs() < 1e-15);
        assert_eq!(s.weight(&[0.0, 1.0]), 0.0, "wrong length: off");
    }

    /// The weight's gradient against central differences across the fade (1-D and 3-D).
    #[test]
    fn weight_gradient_matches_differences() {
        let q: Vec<f64> = (0..21).map(|i| i as f64 * 0.1).collect();
        let s = Support::of(&q, 1, 3).unwrap();
        // Points inside the fade of the outermost centres (not on its edges, where the slope is 0
        // and a central difference straddles the kink of the clamp), inside, and far outside.
        let last = s.centres.iter().fold(f64::NEG_INFINITY, |m, v| m.max(*v));
        let first = s.centres.iter().fold(f64::INFINITY, |m, v| m.min(*v));
        let width = s.outer_rad - s.inner_rad;
        for x in [
            last + s.inner_rad + 0.37 * width,
            first - s.inner_rad - 0.81 * width,
            1.0,
            10.0,
        ] {
            let h = 1e-7;
            let fd = (s.weight(&[x + h]) - s.weight(&[x - h])) / (2.0 * h);
            let mut g = [0.0];
            assert_eq!(s.weight_and_gradient(&[x], &mut g), s.weight(&[x]));
            assert!((g[0] - fd).abs() < 1e-6, "{x}: {} against {fd}", g[0]);
        }
        let q3: Vec<f64> = (0..60).map(|i| ((i * 13) % 17) as f64 * 0.05).collect();
        let s = Support::of(&q3, 3, 1).unwrap();
        let mid = 0.5 * (s.inner_rad + s.outer_rad);
        let p = [q3[0] + mid * 0.6, q3[1] - mid * 0.8, q3[2] + 0.3 * mid];
        let mut g = [0.0; 3];
        assert_eq!(s.weight_and_gradient(&p, &mut g), s.weight(&p));
        for k in 0..3 {
            let h = 1e-7;
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let fd = (s.weight(&a) - s.weight(&b)) / (2.0 * h);
            assert!((g[k] - fd).abs() < 1e-6, "joint {k}: {} against {fd}", g[k]);
        }
    }

    /// Repeated rows count once; a single configuration has a point support.
    #[test]
    fn repeats_and_a_single_configuration() {
        let q = [0.5, 0.5, 0.5, 0.5];
        let s = Support::of(&q, 2, 0).unwrap();
        assert_eq!(s.n_training, 1);
        assert_eq!(s.n_centres(), 1);
        assert_eq!(s.weight(&[0.5, 0.5]), 1.0);
        assert_eq!(s.weight(&[0.5, 1.5]), 0.0);
        assert!(Support::of(&[f64::NAN], 1, 0).is_none());
        assert!(Support::of(&[], 1, 0).is_none());
    }

    /// More configurations than centres: the covering radius doubles and still covers all.
    #[test]
    fn covering_is_capped() {
        // A line of configurations 1 mm apart: covering it at the scale (1e-3) takes n/2 centres.
        let n = 3 * MAX_CENTRES;
        let q: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let s = Support::of(&q, 1, 1).unwrap();
        assert!(s.n_centres() <= MAX_CENTRES);
        assert!(s.cover_rad > s.scale_rad);
        for &v in q.iter().step_by(97) {
            assert!(s.distance(&[v]) <= s.cover_rad + 1e-12);
        }
    }

    /// Same seed, same support; the check accepts it and refuses broken radii.
    #[test]
    fn deterministic_and_checked() {
        let q: Vec<f64> = (0..300).map(|i| ((i * 37) % 101) as f64 * 0.013).collect();
        let a = Support::of(&q, 3, 9).unwrap();
        assert_eq!(a, Support::of(&q, 3, 9).unwrap());
        assert!(a.check().is_ok());
        let mut b = a.clone();
        b.outer_rad = b.inner_rad;
        assert!(b.check().is_err());
        let mut c = a;
        c.centres.push(1.0);
        assert!(c.check().is_err());
    }
}
