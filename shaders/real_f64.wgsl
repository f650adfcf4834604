// The scalar type of shaders/batch.wgsl: f64 (needs the adapter feature SHADER_F64).
//
// WGSL (and SPIR-V's GLSL.std.450) has no f64 sin/cos, so they are computed here: the argument is
// reduced to r in [-π/4, π/4] by x = k·π/2 + r (π/2 split in two parts, Cody–Waite, so that
// k·π/2 is subtracted exactly for |k| < 2^20), then the minimax polynomials of fdlibm's
// __kernel_sin/__kernel_cos (error below 1 ulp on that interval), then the quadrant k mod 4 picks
// ±sin r or ±cos r. Joint angles are a few radians, far inside the exact reduction range.
alias real = f64;

const PIO2_HI: f64 = 1.57079632673412561417e+00;
const PIO2_LO: f64 = 6.07710050650619224932e-11;
const TWO_OVER_PI: f64 = 6.36619772367581382433e-01;

fn ksin(r: f64) -> f64 {
    let z = r * r;
    let p = -1.66666666666666324348e-01 + z * (8.33333333332248946124e-03 + z * (-1.98412698298579493134e-04
        + z * (2.75573137070700676789e-06 + z * (-2.50507602534068634195e-08 + z * 1.58969099521155010221e-10))));
    return r + r * z * p;
}

fn kcos(r: f64) -> f64 {
    let z = r * r;
    let p = 4.16666666666666019037e-02 + z * (-1.38888888888741095749e-03 + z * (2.48015872894767294178e-05
        + z * (-2.75573143513906633035e-07 + z * (2.08757232129817482790e-09 + z * -1.13596475577881948265e-11))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    return w + (((1.0 - w) - hz) + z * z * p);
}

// x = k·π/2 + r; returns (r, k mod 4).
fn reduce(x: f64) -> vec2<f64> {
    let k = floor(x * TWO_OVER_PI + 0.5);
    let r = (x - k * PIO2_HI) - k * PIO2_LO;
    let q = k - 4.0 * floor(k * 0.25);
    return vec2<f64>(r, q);
}

fn sn(x: f64) -> f64 {
    let rq = reduce(x);
    let q = u32(rq.y);
    if (q == 0u) {
        return ksin(rq.x);
    } else if (q == 1u) {
        return kcos(rq.x);
    } else if (q == 2u) {
        return -ksin(rq.x);
    }
    return -kcos(rq.x);
}

fn cs(x: f64) -> f64 {
    let rq = reduce(x);
    let q = u32(rq.y);
    if (q == 0u) {
        return kcos(rq.x);
    } else if (q == 1u) {
        return -ksin(rq.x);
    } else if (q == 2u) {
        return -kcos(rq.x);
    }
    return ksin(rq.x);
}
