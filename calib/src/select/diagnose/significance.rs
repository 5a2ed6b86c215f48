//! The statistics diagnose decides with: a paired test of two models' held-out errors, the training
//! `χ²` drop of nested models, and the normal quantiles they are compared with.

/// Upper-tail standard normal quantile `z` with `P(Z > z) = p`, for `0 < p < 1`.
pub fn normal_upper_quantile(p: f64) -> f64 {
    -normal_quantile(p)
}

/// Standard normal quantile `Φ⁻¹(p)`, `0 < p < 1` (Acklam's rational approximation, relative error
/// below 1.2e-9).
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.383_577_518_672_69e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let lo = 0.02425;
    if p < lo {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - lo {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        let q = (-2.0 * (1.0 - p).ln()).sqrt();
        -(((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    }
}

/// The standard-normal equivalent of a `χ²` value `x` with `k` degrees of freedom (Wilson–Hilferty:
/// `(x/k)^{1/3}` is nearly normal with mean `1 − 2/(9k)` and variance `2/(9k)`).
pub fn chi2_to_z(x: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return 0.0;
    }
    let v = 2.0 / (9.0 * k);
    ((x.max(0.0) / k).cbrt() - (1.0 - v)) / v.sqrt()
}

/// Paired comparison of two models on the same held-out poses.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairedTest {
    /// Poses compared.
    pub n: usize,
    /// Mean reduction of the squared position error per pose (m²).
    pub mean_reduction_m2: f64,
    /// `mean / (sd / √n)`: large and positive when the second model predicts the poses better.
    pub z: f64,
}

/// Paired test of the per-pose squared errors `before[k]` and `after[k]` (m²): is `after` smaller?
pub fn paired(before: &[f64], after: &[f64]) -> PairedTest {
    let n = before.len().min(after.len());
    if n < 2 {
        return PairedTest {
            n,
            mean_reduction_m2: 0.0,
            z: 0.0,
        };
    }
    let d: Vec<f64> = before.iter().zip(after).map(|(b, a)| b - a).collect();
    let mean = d.iter().sum::<f64>() / n as f64;
    let var = d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1) as f64;
    let z = if var > 0.0 {
        mean / (var / n as f64).sqrt()
    } else if mean > 0.0 {
        f64::INFINITY
    } else {
        0.0
    };
    PairedTest {
        n,
        mean_reduction_m2: mean,
        z,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantiles_match_tables() {
        // Abramowitz and Stegun, table 26.5.
        for (p, z) in [
            (0.5, 0.0),
            (0.975, 1.959_963_984_540_054),
            (0.999, 3.090_232_306_167_813),
            (1e-6, -4.753_424_308_822_899),
        ] {
            assert!((normal_quantile(p) - z).abs() < 1e-8, "p = {p}");
        }
        assert!((normal_upper_quantile(0.001) - 3.090_232_306_167_813).abs() < 1e-8);
    }

    #[test]
    fn wilson_hilferty_matches_chi2_quantiles() {
        // χ² upper 0.1 % points (k = 7: 24.322, k = 20: 45.315) map to z ≈ 3.09.
        assert!((chi2_to_z(24.322, 7.0) - 3.09).abs() < 0.05);
        assert!((chi2_to_z(45.315, 20.0) - 3.09).abs() < 0.03);
        assert!(chi2_to_z(7.0, 7.0).abs() < 0.3);
    }

    #[test]
    fn paired_test_sees_a_shift_and_not_noise() {
        let before: Vec<f64> = (0..100)
            .map(|k| 1.0 + 0.1 * ((k * 37 % 11) as f64))
            .collect();
        let same = paired(&before, &before);
        assert_eq!(same.z, 0.0);
        let after: Vec<f64> = before.iter().map(|b| b - 0.5).collect();
        assert!(paired(&before, &after).z.is_infinite());
        let worse: Vec<f64> = before.iter().map(|b| b * 1.1).collect();
        assert!(paired(&before, &worse).z < 0.0);
    }
}
