//! Small fixed-size vector helpers shared by the realtime code (no allocation, `no_std`).

use crate::nurbs::MAX_DIM;

/// A point or derivative with up to [`MAX_DIM`] coordinates; unused trailing entries are zero.
pub type Vector = [f64; MAX_DIM];

/// Euclidean norm of the first `n` coordinates.
#[inline]
pub fn norm(v: &Vector, n: usize) -> f64 {
    libm::sqrt(dot(v, v, n))
}

/// Dot product of the first `n` coordinates.
#[inline]
pub fn dot(a: &Vector, b: &Vector, n: usize) -> f64 {
    let mut s = 0.0;
    for i in 0..n {
        s += a[i] * b[i];
    }
    s
}

/// `a - b` over all coordinates.
#[inline]
pub fn sub(a: &Vector, b: &Vector) -> Vector {
    let mut r = [0.0; MAX_DIM];
    for i in 0..MAX_DIM {
        r[i] = a[i] - b[i];
    }
    r
}

/// Binomial coefficient for the small orders used by the quotient rule.
#[inline]
pub fn binomial(n: usize, k: usize) -> f64 {
    let mut r = 1.0;
    for i in 0..k {
        r = r * (n - i) as f64 / (i + 1) as f64;
    }
    r
}
