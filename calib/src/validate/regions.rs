//! Regions of the configuration space, for validation on poses unlike the ones a fit saw.
//!
//! Random k-fold validation by pose tests a model only between the poses it was fitted on. Where the
//! poses lie on a low-dimensional manifold (a grid at one flange orientation, as the UR10 series are),
//! a learned correction fits the manifold and the folds never leave it. Holding out whole **regions**
//! tests what a user meets who calibrates once and works elsewhere in the workspace.
//!
//! The regions: every distinct pose (campaign, pose id) is the point `(sin q₁, cos q₁, …, sin qₙ,
//! cos qₙ)` of its first row (so a joint's angle counts on the circle, and `q` and `q + 2π` are one
//! point), and the points are clustered into `K` regions by k-means:
//!
//! 1. **k-means++ seeding** (Arthur and Vassilvitskii, 2007) with a generator seeded by `seed`: the first
//!    centre is a uniformly drawn point, each next one a point drawn with probability proportional to
//!    its squared distance to the nearest centre so far;
//! 2. **Lloyd iterations**: each point to its nearest centre (ties to the lower index), each centre to
//!    the mean of its points (a centre that loses every point stays where it was), until no point
//!    changes region or [`MAX_ITERATIONS`] rounds.
//!
//! The assignment is a pure function of the poses, their order and the seed; the means are summed in
//! pose order, so it does not depend on the thread count.

use rand::RngExt;
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;

/// Default number of regions (`--regions`).
pub const DEFAULT_REGIONS: usize = 5;
/// Most Lloyd rounds.
pub const MAX_ITERATIONS: usize = 100;
/// Most points the centres are fitted on: beyond, a seeded sample of this many places the centres
/// and every point then goes to its nearest centre (the regions of 10⁵ poses in a fraction of the
/// time, with the same shape).
pub const MAX_FIT_POINTS: usize = 10_000;

/// The clustering point of a configuration `q` (rad): `(sin q₁, cos q₁, …)`.
pub fn features(q: &[f64], out: &mut Vec<f64>) {
    for v in q {
        out.push(v.sin());
        out.push(v.cos());
    }
}

fn dist2(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// Region (0..`k`) of every point of `points` (row-major, `dim` per point) by seeded k-means++ and
/// Lloyd iterations (module docs). With fewer distinct points than `k`, some regions stay empty.
///
/// # Panics
/// If `k == 0`, `dim == 0` or `points.len()` is not a multiple of `dim`.
pub fn kmeans(points: &[f64], dim: usize, k: usize, seed: u64) -> Vec<usize> {
    assert!(
        k > 0 && dim > 0 && points.len().is_multiple_of(dim),
        "k-means input"
    );
    let n = points.len() / dim;
    if n <= MAX_FIT_POINTS {
        let mut rng = StdRng::seed_from_u64(seed ^ 0x0072_6567_696f_6e73);
        return kmeans_with(points, dim, k, &mut rng).1;
    }
    nearest_centres(points, dim, &centres(points, dim, k, seed))
}

/// The centres (row-major, `dim` per centre; fewer than `k` with fewer distinct points) that
/// [`kmeans`] places for `points` with `seed`: every point of `points` lies nearest the centre of
/// its region there (for a clustering that converged within [`MAX_ITERATIONS`] rounds). What a
/// streamed validation keeps to give each row of a file its region ([`nearest_centre`]).
///
/// # Panics
/// As [`kmeans`].
pub fn centres(points: &[f64], dim: usize, k: usize, seed: u64) -> Vec<f64> {
    assert!(
        k > 0 && dim > 0 && points.len().is_multiple_of(dim),
        "k-means input"
    );
    let n = points.len() / dim;
    let mut rng = StdRng::seed_from_u64(seed ^ 0x0072_6567_696f_6e73);
    if n <= MAX_FIT_POINTS {
        return kmeans_with(points, dim, k, &mut rng).0;
    }
    let mut sample: Vec<usize> = (0..n).collect();
    sample.shuffle(&mut rng);
    sample.truncate(MAX_FIT_POINTS);
    sample.sort_unstable();
    let fit_points: Vec<f64> = sample
        .iter()
        .flat_map(|&i| points[i * dim..(i + 1) * dim].iter().copied())
        .collect();
    kmeans_with(&fit_points, dim, k, &mut rng).0
}

/// The region of `point` (`dim` values): its nearest centre of `centres` (ties to the lower index),
/// as [`kmeans`] assigns every point.
pub fn nearest_centre(point: &[f64], centres: &[f64], dim: usize) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (c, centre) in centres.chunks(dim).enumerate() {
        let d = dist2(point, centre);
        if d < best.0 {
            best = (d, c);
        }
    }
    best.1
}

/// Nearest centre (ties to the lower index) of every point.
fn nearest_centres(points: &[f64], dim: usize, centres: &[f64]) -> Vec<usize> {
    points
        .par_chunks(dim)
        .map(|p| nearest_centre(p, centres, dim))
        .collect()
}

/// k-means++ and Lloyd on every point of `points`: the centres and the regions.
fn kmeans_with(points: &[f64], dim: usize, k: usize, rng: &mut StdRng) -> (Vec<f64>, Vec<usize>) {
    let n = points.len() / dim;
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let point = |i: usize| &points[i * dim..(i + 1) * dim];
    // k-means++ seeding.
    let mut centres: Vec<f64> = Vec::with_capacity(k * dim);
    centres.extend_from_slice(point(rng.random_range(0..n)));
    let mut nearest: Vec<f64> = (0..n).map(|i| dist2(point(i), &centres[..dim])).collect();
    while centres.len() < k * dim {
        let total: f64 = nearest.iter().sum();
        if total <= 0.0 {
            break; // every point sits on a centre: fewer distinct points than regions
        }
        let mut target = rng.random::<f64>() * total;
        let mut chosen = n - 1;
        for (i, d) in nearest.iter().enumerate() {
            if target < *d {
                chosen = i;
                break;
            }
            target -= d;
        }
        let c = point(chosen).to_vec();
        for (i, d) in nearest.iter_mut().enumerate() {
            *d = d.min(dist2(point(i), &c));
        }
        centres.extend_from_slice(&c);
    }
    let k_used = centres.len() / dim;
    let assign = |centres: &[f64]| nearest_centres(points, dim, centres);
    let mut region = assign(&centres);
    for _ in 0..MAX_ITERATIONS {
        let mut sums = vec![0.0; k_used * dim];
        let mut counts = vec![0usize; k_used];
        for (i, &r) in region.iter().enumerate() {
            counts[r] += 1;
            for (s, v) in sums[r * dim..(r + 1) * dim].iter_mut().zip(point(i)) {
                *s += v;
            }
        }
        for r in 0..k_used {
            if counts[r] > 0 {
                for j in 0..dim {
                    centres[r * dim + j] = sums[r * dim + j] / counts[r] as f64;
                }
            }
        }
        let next = assign(&centres);
        if next == region {
            break;
        }
        region = next;
    }
    (centres, region)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three well-separated blobs in 2-D are found exactly, whatever the seed.
    #[test]
    fn separated_blobs_are_found() {
        let mut pts = Vec::new();
        let centres = [(0.0, 0.0), (10.0, 0.0), (0.0, 10.0)];
        for (b, (cx, cy)) in centres.iter().enumerate() {
            for i in 0..20 {
                let a = i as f64 * 0.7 + b as f64;
                pts.push(cx + 0.3 * a.sin());
                pts.push(cy + 0.3 * a.cos());
            }
        }
        for seed in 0..10 {
            let r = kmeans(&pts, 2, 3, seed);
            for b in 0..3 {
                let first = r[b * 20];
                assert!(r[b * 20..(b + 1) * 20].iter().all(|&x| x == first));
            }
            assert_ne!(r[0], r[20]);
            assert_ne!(r[0], r[40]);
            assert_ne!(r[20], r[40]);
        }
    }

    /// Same seed, same regions; the sin/cos features make q and q + 2π one point.
    #[test]
    fn deterministic_and_on_the_circle() {
        let mut a = Vec::new();
        let mut b = Vec::new();
        for i in 0..50 {
            let q = [i as f64 * 0.13, (i * 7 % 11) as f64 * 0.3];
            features(&q, &mut a);
            features(&[q[0] + std::f64::consts::TAU, q[1]], &mut b);
        }
        let ra = kmeans(&a, 4, 5, 42);
        assert_eq!(ra, kmeans(&a, 4, 5, 42));
        // q and q + 2π are one point (to rounding, which may break an exact tie either way).
        assert!(a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-12));
        assert!(ra.iter().all(|&r| r < 5));
        let used: std::collections::HashSet<usize> = ra.iter().copied().collect();
        assert_eq!(used.len(), 5, "every region has points");
    }

    /// Fewer distinct points than regions: no panic, every point in a region.
    #[test]
    fn fewer_points_than_regions() {
        let pts = [1.0, 1.0, 1.0, 1.0, 2.0, 2.0];
        let r = kmeans(&pts, 2, 5, 0);
        assert_eq!(r.len(), 3);
        assert_eq!(r[0], r[1]);
        assert_ne!(r[0], r[2]);
    }
}
