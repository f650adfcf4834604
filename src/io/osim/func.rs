//! OpenSim functions → [`Function`], with SimmSpline's own coefficient algorithm.

use super::xml::{child, elements, Ctx};
use super::OsimError;
use crate::model::{CubicSpline, Function};
use roxmltree::Node;

/// The OpenSim function element types this reader understands.
pub(super) const SUPPORTED: [&str; 7] = [
    "Constant",
    "LinearFunction",
    "SimmSpline",
    "NaturalCubicSpline",
    "PolynomialFunction",
    "PiecewiseLinearFunction",
    "MultiplierFunction",
];

/// Finds and parses the function element among `node`'s children: a `<function>` wrapper
/// around one, else the first child element whose tag is not in `skip`. `Ok(None)` when none.
pub(super) fn child_function<'a>(
    ctx: &Ctx<'a>,
    node: Node<'a, 'a>,
    skip: &[&str],
) -> Result<Option<Function>, OsimError> {
    let f = match child(node, "function") {
        Some(w) => elements(w).next(),
        None => elements(node).find(|n| !skip.contains(&n.tag_name().name())),
    };
    f.map(|f| parse_function(ctx, f)).transpose()
}

/// Parses one function element (`<SimmSpline>`, `<LinearFunction>`, …).
pub(super) fn parse_function<'a>(ctx: &Ctx<'a>, f: Node<'a, 'a>) -> Result<Function, OsimError> {
    parse_depth(ctx, f, 0)
}

fn parse_depth<'a>(ctx: &Ctx<'a>, f: Node<'a, 'a>, depth: usize) -> Result<Function, OsimError> {
    match f.tag_name().name() {
        "Constant" => Ok(Function::Constant { value: ctx.scalar(f, "value")?.unwrap_or(0.0) }),
        "LinearFunction" => {
            let c = ctx.fixed(f, "coefficients", 2, false)?.unwrap_or_else(|| vec![1.0, 0.0]);
            Ok(Function::Linear { slope: c[0], intercept: c[1] })
        }
        "PolynomialFunction" => {
            // OpenSim lists the coefficients from the highest order down.
            let mut c = ctx.nums(f, "coefficients", false)?.unwrap_or_else(|| vec![1.0]);
            if c.is_empty() {
                return Err(ctx.err(f, "a polynomial needs at least one coefficient"));
            }
            c.reverse();
            Ok(Function::Polynomial { coefficients: c })
        }
        "SimmSpline" | "NaturalCubicSpline" | "PiecewiseLinearFunction" => {
            let (x, y) = knots(ctx, f)?;
            Ok(match f.tag_name().name() {
                "SimmSpline" => simm_spline(&x, &y),
                "NaturalCubicSpline" => match CubicSpline::natural(&x, &y) {
                    Some(s) => Function::Spline(s),
                    None => return Err(ctx.err(f, "invalid knots")),
                },
                _ => Function::PiecewiseLinear { x, y },
            })
        }
        "MultiplierFunction" => {
            if depth > 16 {
                return Err(ctx.err(f, "MultiplierFunction nested too deeply"));
            }
            let scale = ctx.scalar(f, "scale")?.unwrap_or(1.0);
            let inner = child(f, "function").and_then(|w| elements(w).next());
            let Some(inner) = inner else {
                return Err(ctx.err(f, "MultiplierFunction without a <function>"));
            };
            Ok(match parse_depth(ctx, inner, depth + 1)? {
                Function::Constant { value } => Function::Constant { value: scale * value },
                Function::Multiplier { scale: s2, inner } => Function::Multiplier { scale: scale * s2, inner },
                inner => Function::Multiplier { scale, inner: Box::new(inner) },
            })
        }
        other => {
            Err(ctx.err(f, format!("unsupported function type '{other}': expected one of {}", SUPPORTED.join(", "))))
        }
    }
}

/// Knots `<x>`, `<y>`: same length ≥ 2, strictly increasing `x`, finite.
fn knots<'a>(ctx: &Ctx<'a>, f: Node<'a, 'a>) -> Result<(Vec<f64>, Vec<f64>), OsimError> {
    let x = ctx.nums(f, "x", false)?.unwrap_or_default();
    let y = ctx.nums(f, "y", false)?.unwrap_or_default();
    if x.len() != y.len() || x.len() < 2 {
        return Err(
            ctx.err(f, format!("needs at least 2 knots with as many x as y (got {} x, {} y)", x.len(), y.len()))
        );
    }
    if x.windows(2).any(|w| w[1] <= w[0]) {
        return Err(ctx.err(f, "knot x values must be strictly increasing"));
    }
    Ok((x, y))
}

/// OpenSim `SimmSpline` (SIMM's cubic spline; end third derivatives matched to divided
/// differences, as in Forsythe–Malcolm–Moler `spline`), as a [`CubicSpline`]. Needs ≥ 2
/// strictly increasing knots. Evaluation matches `SimmSpline::calcValue`: cubic on each
/// segment, linear extrapolation with the end slopes `b[0]`, `b[n−1]`.
pub fn simm_spline(x: &[f64], y: &[f64]) -> Function {
    let n = x.len();
    if n < 2 || y.len() != n {
        return Function::Constant { value: y.first().copied().unwrap_or(0.0) };
    }
    if n == 2 {
        let slope = (y[1] - y[0]) / (x[1] - x[0]);
        return Function::Linear { slope, intercept: y[0] - slope * x[0] };
    }
    let (nm1, nm2) = (n - 1, n - 2);
    let (mut b, mut c, mut d) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    // Tridiagonal system: b = diagonal, d = off-diagonal, c = right-hand side.
    d[0] = x[1] - x[0];
    c[1] = (y[1] - y[0]) / d[0];
    for i in 1..nm1 {
        d[i] = x[i + 1] - x[i];
        b[i] = 2.0 * (d[i - 1] + d[i]);
        c[i + 1] = (y[i + 1] - y[i]) / d[i];
        c[i] = c[i + 1] - c[i];
    }
    // End conditions: third derivatives at the ends from divided differences.
    b[0] = -d[0];
    b[nm1] = -d[nm2];
    c[0] = 0.0;
    c[nm1] = 0.0;
    if n > 3 {
        let d31 = x[3] - x[1];
        let d20 = x[2] - x[0];
        let d1 = x[nm1] - x[n - 3];
        let d2 = x[nm2] - x[n - 4];
        let d30 = x[3] - x[0];
        let d3 = x[nm1] - x[n - 4];
        c[0] = c[2] / d31 - c[1] / d20;
        c[nm1] = c[nm2] / d1 - c[n - 3] / d2;
        c[0] = c[0] * d[0] * d[0] / d30;
        c[nm1] = -c[nm1] * d[nm2] * d[nm2] / d3;
    }
    // Forward elimination.
    for i in 1..n {
        let t = d[i - 1] / b[i - 1];
        b[i] -= t * d[i - 1];
        c[i] -= t * c[i - 1];
    }
    // Back substitution.
    c[nm1] /= b[nm1];
    for i in (0..nm1).rev() {
        c[i] = (c[i] - d[i] * c[i + 1]) / b[i];
    }
    // Polynomial coefficients.
    b[nm1] = (y[nm1] - y[nm2]) / d[nm2] + d[nm2] * (c[nm2] + 2.0 * c[nm1]);
    for i in 0..nm1 {
        b[i] = (y[i + 1] - y[i]) / d[i] - d[i] * (c[i + 1] + 2.0 * c[i]);
        d[i] = (c[i + 1] - c[i]) / d[i];
        c[i] *= 3.0;
    }
    c[nm1] *= 3.0;
    d[nm1] = d[nm2];
    Function::Spline(CubicSpline { x: x.to_vec(), a: y.to_vec(), b, c, d })
}
