//! Placeholder until the fast kernel lands: std's sine and cosine.

/// `(sin x, cos x)` for `x` in rad.
#[inline]
pub fn sin_cos(x: f64) -> (f64, f64) {
    x.sin_cos()
}
