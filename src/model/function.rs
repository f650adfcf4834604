//! Scalar functions that drive elementary joint motions from coordinates, and proxy couplings.
//!
//! Every function returns its value and first derivative analytically; importers map their
//! function kinds (OpenSim `LinearFunction`, `SimmSpline`, ..., MuJoCo `polycoef`) onto these.

use serde::{Deserialize, Serialize};

/// A differentiable scalar function `f(x)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Function {
    /// `f(x) = value`.
    Constant { value: f64 },
    /// `f(x) = slope · x + intercept` (identity: slope 1, intercept 0).
    Linear { slope: f64, intercept: f64 },
    /// `f(x) = c0 + c1 x + c2 x² + …` (coefficients in increasing order).
    Polynomial { coefficients: Vec<f64> },
    /// Natural cubic spline through knots `(x[i], y[i])`, extrapolated linearly outside.
    Spline(CubicSpline),
    /// Straight segments between knots, constant slope extrapolation outside.
    PiecewiseLinear { x: Vec<f64>, y: Vec<f64> },
    /// `f(x) = scale · inner(x)`.
    Multiplier { scale: f64, inner: Box<Function> },
}

impl Function {
    /// The identity `f(x) = x`.
    pub const IDENTITY: Function = Function::Linear { slope: 1.0, intercept: 0.0 };

    /// Value and derivative `(f(x), f'(x))`.
    ///
    /// ```
    /// use smocap::model::Function;
    /// let f = Function::Polynomial { coefficients: vec![1.0, 2.0, 3.0] }; // 1 + 2x + 3x²
    /// assert_eq!(f.eval(2.0), (17.0, 14.0));
    /// ```
    #[inline]
    pub fn eval(&self, x: f64) -> (f64, f64) {
        match self {
            Function::Constant { value } => (*value, 0.0),
            Function::Linear { slope, intercept } => (slope * x + intercept, *slope),
            Function::Polynomial { coefficients } => {
                // Horner on value and derivative together.
                let (mut v, mut d) = (0.0, 0.0);
                for &c in coefficients.iter().rev() {
                    d = d * x + v;
                    v = v * x + c;
                }
                (v, d)
            }
            Function::Spline(s) => s.eval(x),
            Function::PiecewiseLinear { x: xs, y: ys } => piecewise_linear(xs, ys, x),
            Function::Multiplier { scale, inner } => {
                let (v, d) = inner.eval(x);
                (scale * v, scale * d)
            }
        }
    }

    /// True when `f` does not depend on its argument.
    pub fn is_constant(&self) -> bool {
        matches!(self, Function::Constant { .. })
    }
}

fn piecewise_linear(xs: &[f64], ys: &[f64], x: f64) -> (f64, f64) {
    let n = xs.len();
    if n == 0 {
        return (0.0, 0.0);
    }
    if n == 1 {
        return (ys[0], 0.0);
    }
    let i = segment_index(xs, x);
    let slope = (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i]);
    (ys[i] + slope * (x - xs[i]), slope)
}

/// Index `i` of the segment `[xs[i], xs[i+1]]` used for `x` (clamped to the end segments).
fn segment_index(xs: &[f64], x: f64) -> usize {
    let n = xs.len();
    match xs.partition_point(|&k| k <= x) {
        0 => 0,
        p if p >= n => n - 2,
        p => p - 1,
    }
}

/// Cubic spline `y = a + b t + c t² + d t³`, `t = x − x[i]`, on each segment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CubicSpline {
    pub x: Vec<f64>,
    pub a: Vec<f64>,
    pub b: Vec<f64>,
    pub c: Vec<f64>,
    pub d: Vec<f64>,
}

impl CubicSpline {
    /// Natural cubic spline (zero second derivative at both ends) through the knots.
    /// Needs at least two knots with strictly increasing `x`; returns `None` otherwise.
    pub fn natural(x: &[f64], y: &[f64]) -> Option<CubicSpline> {
        let n = x.len();
        if n < 2 || y.len() != n || x.windows(2).any(|w| w[1] <= w[0]) {
            return None;
        }
        let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        // Tridiagonal system for second derivatives m[1..n-1] (m[0] = m[n-1] = 0).
        let mut m = vec![0.0; n];
        if n > 2 {
            let k = n - 2;
            let mut diag = vec![0.0; k];
            let mut rhs = vec![0.0; k];
            for i in 0..k {
                diag[i] = 2.0 * (h[i] + h[i + 1]);
                rhs[i] = 6.0 * ((y[i + 2] - y[i + 1]) / h[i + 1] - (y[i + 1] - y[i]) / h[i]);
            }
            for i in 1..k {
                let w = h[i] / diag[i - 1];
                diag[i] -= w * h[i];
                rhs[i] -= w * rhs[i - 1];
            }
            m[k] = rhs[k - 1] / diag[k - 1];
            for i in (0..k - 1).rev() {
                m[i + 1] = (rhs[i] - h[i + 1] * m[i + 2]) / diag[i];
            }
        }
        let mut s = CubicSpline { x: x.to_vec(), a: y.to_vec(), b: vec![0.0; n], c: vec![0.0; n], d: vec![0.0; n] };
        for i in 0..n - 1 {
            s.b[i] = (y[i + 1] - y[i]) / h[i] - h[i] * (2.0 * m[i] + m[i + 1]) / 6.0;
            s.c[i] = m[i] / 2.0;
            s.d[i] = (m[i + 1] - m[i]) / (6.0 * h[i]);
        }
        // Slope at the last knot, for linear extrapolation.
        let i = n - 2;
        s.b[n - 1] = s.b[i] + 2.0 * s.c[i] * h[i] + 3.0 * s.d[i] * h[i] * h[i];
        Some(s)
    }

    /// Value and derivative; linear extrapolation outside the knots.
    #[inline]
    pub fn eval(&self, x: f64) -> (f64, f64) {
        let n = self.x.len();
        if x <= self.x[0] {
            return (self.a[0] + self.b[0] * (x - self.x[0]), self.b[0]);
        }
        if x >= self.x[n - 1] {
            return (self.a[n - 1] + self.b[n - 1] * (x - self.x[n - 1]), self.b[n - 1]);
        }
        let i = segment_index(&self.x, x);
        let t = x - self.x[i];
        let v = self.a[i] + t * (self.b[i] + t * (self.c[i] + t * self.d[i]));
        let dv = self.b[i] + t * (2.0 * self.c[i] + 3.0 * t * self.d[i]);
        (v, dv)
    }
}
