// What both kernels share: bindings, buffer addressing, the model's functions, and the steps of
// forward kinematics and Jacobian assembly for one body, one layout body's chain and one marker.
// The mirror of src/kinematics/{cpu,assembly}.rs and src/model/proxy.rs in the scalar type `real`:
// f32, or f64 where the adapter offers SHADER_F64 and it is asked for. The host prepends
// shaders/real_f32.wgsl or shaders/real_f64.wgsl, which define `real` and its `sn`/`cs` (WGSL has
// no f64 sin/cos), and appends one kernel: shaders/cooperative.wgsl (one workgroup per frame, the
// default) or shaders/per_frame.wgsl (one invocation per frame). Each kernel defines `at(row, f)`,
// where scratch entry `row` of frame `f` lives. See docs/KINEMATICS.md for the math and the cost
// model, src/kinematics/gpu/pack.rs for the buffer layouts.
//
// The host prepends a header of `const` declarations (sizes and section offsets of one model, and
// the chunk capacity `CAP` the buffers hold). Input and output are frame-major (one block per
// frame, which the host writes and reads in place).
//
// Positions are relative to a per-frame reference point `c` (subtracted in f64 on the host), so
// that f32 carries the body-scale differences rather than lab-scale coordinates; Jacobian rows
// are formed relative to the body origin (`a + w × x = (a + w × c_b) + w × (x − c_b)`), which
// avoids cancelling two world-sized terms.

struct Params {
    // Frames in this chunk (≤ CAP).
    n: u32,
    // Structure-of-arrays stride of this chunk (≤ CAP).
    stride: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read> mu: array<u32>;
@group(0) @binding(1) var<storage, read> mf: array<real>;
@group(0) @binding(2) var<storage, read> inp: array<real>;
@group(0) @binding(3) var<storage, read_write> scr: array<real>;
@group(0) @binding(4) var<storage, read_write> outb: array<real>;
@group(0) @binding(5) var<uniform> params: Params;

const NONE: u32 = 0xffffffffu;

// Input: one block of IN_ROWS words per frame.
fn ai(row: u32, f: u32) -> u32 {
    return f * IN_ROWS + row;
}

// Output: the compact energy rows (4 words per frame, CAP frames), then one block of OUT_ROWS
// words per frame.
fn ao(row: u32, f: u32) -> u32 {
    return 4u * CAP + f * OUT_ROWS + row;
}

fn mf3(i: u32) -> vec3<real> {
    return vec3<real>(mf[i], mf[i + 1u], mf[i + 2u]);
}

fn mf33(i: u32) -> mat3x3<real> {
    return mat3x3<real>(mf3(i), mf3(i + 3u), mf3(i + 6u));
}

fn s3(row: u32, f: u32) -> vec3<real> {
    return vec3<real>(scr[at(row, f)], scr[at(row + 1u, f)], scr[at(row + 2u, f)]);
}

fn put3(row: u32, f: u32, v: vec3<real>) {
    scr[at(row, f)] = v.x;
    scr[at(row + 1u, f)] = v.y;
    scr[at(row + 2u, f)] = v.z;
}

fn rot(b: u32, f: u32) -> mat3x3<real> {
    let r = S_ROT + 9u * b;
    return mat3x3<real>(s3(r, f), s3(r + 3u, f), s3(r + 6u, f));
}

fn scale(b: u32, f: u32) -> vec3<real> {
    return s3(S_Y + NQ + 3u * b, f);
}

// Index of the segment [x[i], x[i+1]] of n sorted knots at `xs` used for `x` (clamped to the ends).
fn segment(xs: u32, n: u32, x: real) -> u32 {
    var p = 0u;
    while (p < n && mf[xs + p] <= x) {
        p += 1u;
    }
    if (p == 0u) {
        return 0u;
    }
    if (p >= n) {
        return n - 2u;
    }
    return p - 1u;
}

// Value and derivative of function `fi` at `x` (src/model/function.rs; multipliers are folded
// into the scale stored first among the parameters).
fn feval(fi: u32, x: real) -> vec2<real> {
    let kind = mu[U_FUNC + 3u * fi];
    let s = mu[U_FUNC + 3u * fi + 1u];
    let n = mu[U_FUNC + 3u * fi + 2u];
    let k = mf[s];
    let p = s + 1u;
    var v: real = 0.0;
    var d: real = 0.0;
    switch kind {
        case 0u: {
            v = mf[p];
        }
        case 1u: {
            v = mf[p] * x + mf[p + 1u];
            d = mf[p];
        }
        case 2u: {
            for (var i = n; i > 0u; i -= 1u) {
                d = d * x + v;
                v = v * x + mf[p + i - 1u];
            }
        }
        case 3u: {
            // Natural cubic spline: x, a, b, c, d arrays of n each; linear outside.
            let last = n - 1u;
            if (x <= mf[p]) {
                v = mf[p + n] + mf[p + 2u * n] * (x - mf[p]);
                d = mf[p + 2u * n];
            } else if (x >= mf[p + last]) {
                v = mf[p + n + last] + mf[p + 2u * n + last] * (x - mf[p + last]);
                d = mf[p + 2u * n + last];
            } else {
                let i = segment(p, n, x);
                let t = x - mf[p + i];
                let a = mf[p + n + i];
                let b = mf[p + 2u * n + i];
                let c = mf[p + 3u * n + i];
                let dd = mf[p + 4u * n + i];
                v = a + t * (b + t * (c + t * dd));
                d = b + t * (2.0 * c + 3.0 * t * dd);
            }
        }
        case 4u: {
            // Piecewise linear: x, y arrays of n each.
            if (n == 1u) {
                v = mf[p + 1u];
            } else if (n >= 2u) {
                let i = segment(p, n, x);
                let slope = (mf[p + n + i + 1u] - mf[p + n + i]) / (mf[p + i + 1u] - mf[p + i]);
                v = mf[p + n + i] + slope * (x - mf[p + i]);
                d = slope;
            }
        }
        default: {}
    }
    return vec2<real>(k * v, k * d);
}

// Rotation by `angle` about unit `axis`.
fn axis_angle(axis: vec3<real>, angle: real) -> mat3x3<real> {
    let c = cs(angle);
    let s = sn(angle);
    let t = 1.0 - c;
    let x = axis.x;
    let y = axis.y;
    let z = axis.z;
    return mat3x3<real>(
        vec3<real>(t * x * x + c, t * x * y + s * z, t * x * z - s * y),
        vec3<real>(t * x * y - s * z, t * y * y + c, t * y * z + s * x),
        vec3<real>(t * x * z + s * y, t * y * z - s * x, t * z * z + c),
    );
}

// The per-frame reference point (the host's `c`).
fn reference(f: u32) -> vec3<real> {
    return vec3<real>(inp[ai(I_C, f)], inp[ai(I_C + 1u, f)], inp[ai(I_C + 2u, f)]);
}

// Body `b`'s frame and its motions' axes, origins and values, from its parent's frame (which must
// be in scratch already) and y.
fn body_frame(b: u32, f: u32, c: vec3<real>) {
    let parent = mu[U_BODY + 3u * b];
    var rp = mat3x3<real>(vec3<real>(1.0, 0.0, 0.0), vec3<real>(0.0, 1.0, 0.0), vec3<real>(0.0, 0.0, 1.0));
    var tp = -c;
    var sp = vec3<real>(1.0, 1.0, 1.0);
    if (parent != NONE) {
        rp = rot(parent, f);
        tp = s3(S_POS + 3u * parent, f);
        sp = scale(parent, f);
    }
    let fb = F_BODY + 24u * b;
    var r = rp * mf33(fb);
    var t = tp + rp * (sp * mf3(fb + 9u));
    for (var m = mu[U_BODY + 3u * b + 1u]; m < mu[U_BODY + 3u * b + 2u]; m += 1u) {
        let kind = mu[U_MOT + 4u * m];
        let coord = mu[U_MOT + 4u * m + 1u];
        var x: real = 0.0;
        if (coord != NONE) {
            x = scr[at(S_Y + coord, f)];
        }
        let vd = feval(mu[U_MOT + 4u * m + 2u], x);
        let axis = mf3(F_MOT + 6u * m);
        let axis_w = r * axis;
        put3(S_MAX + 3u * m, f, axis_w);
        put3(S_MOR + 3u * m, f, t);
        scr[at(S_MVAL + m, f)] = vd.x;
        scr[at(S_MDER + m, f)] = vd.y;
        if (kind == 0u) {
            r = r * axis_angle(axis, vd.x);
        } else {
            var sigma: real = 1.0;
            if (mu[U_MOT + 4u * m + 3u] != 0u) {
                sigma = dot(mf3(F_MOT + 6u * m + 3u), sp);
            }
            scr[at(S_MSIG + m, f)] = sigma;
            t += axis_w * (vd.x * sigma);
        }
    }
    let sb = scale(b, f);
    let rb = r * transpose(mf33(fb + 12u));
    put3(S_POS + 3u * b, f, t - rb * (sb * mf3(fb + 21u)));
    let rr = S_ROT + 9u * b;
    put3(rr, f, rb[0]);
    put3(rr + 3u, f, rb[1]);
    put3(rr + 6u, f, rb[2]);
}

// Model marker `m`'s position (relative to `c`), from its body's frame.
fn marker_position(m: u32, f: u32) -> vec3<real> {
    let b = mu[U_MARK + m];
    return s3(S_POS + 3u * b, f) + rot(b, f) * (scale(b, f) * mf3(F_MARK + 3u * m));
}

// Marker `m`'s contribution to (E, Σ‖r‖², markers used).
fn marker_energy(m: u32, f: u32, x: vec3<real>) -> vec3<real> {
    let w = inp[ai(I_MW + m, f)];
    if (w > 0.0) {
        let o = vec3<real>(inp[ai(I_OBS + 3u * m, f)], inp[ai(I_OBS + 3u * m + 1u, f)], inp[ai(I_OBS + 3u * m + 2u, f)]);
        let d = x - o;
        let d2 = dot(d, d);
        return vec3<real>(0.5 * w * d2, d2, 1.0);
    }
    return vec3<real>(0.0, 0.0, 0.0);
}

// Tracking weight of y entry j in frame f: from the frame's weight set (the sets follow the
// chunk's input blocks, at CAP · IN_ROWS; frames sharing a weight vector share a set).
fn tracking_weight(j: u32, f: u32) -> real {
    return inp[CAP * IN_ROWS + u32(inp[ai(I_TW, f)]) * NY + j];
}

// Tracking term j's contribution to E.
fn tracking_energy(j: u32, f: u32) -> real {
    let w = tracking_weight(j, f);
    if (w > 0.0) {
        let d = scr[at(S_Y + j, f)] - inp[ai(I_TREF + j, f)];
        return 0.5 * w * d * d;
    }
    return 0.0;
}

// Layout body `lb`'s chain, once for all its markers, into scratch rows `aw..aw + 6·ns`: slot s of
// a marker row at a point x on the body is A_s + W_s × (x − c_b).
fn chain(lb: u32, f: u32, aw: u32) {
    let base = U_LB + 7u * lb;
    let ns = mu[base + 1u];
    let cb = s3(S_POS + 3u * mu[base], f);
    for (var s = 0u; s < 6u * ns; s += 1u) {
        scr[at(aw + s, f)] = 0.0;
    }
    for (var it = mu[base + 3u]; it < mu[base + 4u]; it += 1u) {
        let kind = mu[U_ITEM + 5u * it];
        let idx = mu[U_ITEM + 5u * it + 1u];
        let kk = mu[U_ITEM + 5u * it + 2u];
        let d = scr[at(S_DPHI + mu[U_ITEM + 5u * it + 3u], f)];
        let slot = mu[U_ITEM + 5u * it + 4u];
        let coef = mf[F_ITEM + it];
        var a = vec3<real>(0.0, 0.0, 0.0);
        var wv = vec3<real>(0.0, 0.0, 0.0);
        switch kind {
            case 0u: {
                a = rot(idx, f)[kk] * coef;
            }
            case 1u: {
                wv = s3(S_MAX + 3u * idx, f) * scr[at(S_MDER + idx, f)];
                a = cross(wv, cb - s3(S_MOR + 3u * idx, f));
            }
            case 2u: {
                a = s3(S_MAX + 3u * idx, f) * (scr[at(S_MDER + idx, f)] * scr[at(S_MSIG + idx, f)]);
            }
            case 3u: {
                a = s3(S_MAX + 3u * idx, f) * (scr[at(S_MVAL + idx, f)] * coef);
            }
            default: {
                a = -rot(idx, f)[kk] * coef;
            }
        }
        put3(aw + 3u * slot, f, s3(aw + 3u * slot, f) + a * d);
        put3(aw + 3u * (ns + slot), f, s3(aw + 3u * (ns + slot), f) + wv * d);
    }
}

// The rows of J_m of marker entry `q` (of layout body `lb`) into scratch rows `row..row + 3·ns`,
// from its body's chain at `aw`.
fn marker_rows(q: u32, lb: u32, f: u32, aw: u32, row: u32) {
    let base = U_LB + 7u * lb;
    let body = mu[base];
    let ns = mu[base + 1u];
    let m = mu[U_LBM + 3u * q];
    let rb = rot(body, f);
    let off = mf3(F_MARK + 3u * m);
    let xr = rb * (scale(body, f) * off);
    for (var s = 0u; s < ns; s += 1u) {
        put3(row + 3u * s, f, s3(aw + 3u * s, f) + cross(s3(aw + 3u * (ns + s), f), xr));
    }
    for (var oi = mu[U_LBM + 3u * q + 1u]; oi < mu[U_LBM + 3u * q + 2u]; oi += 1u) {
        let kk = mu[U_OITEM + 3u * oi];
        let d = scr[at(S_DPHI + mu[U_OITEM + 3u * oi + 1u], f)];
        let slot = mu[U_OITEM + 3u * oi + 2u];
        put3(row + 3u * slot, f, s3(row + 3u * slot, f) + rb[kk] * (off[kk] * d));
    }
}

// Marker m's residual x − o (model marker from the output, observation from the input).
fn residual(m: u32, f: u32) -> vec3<real> {
    let x = vec3<real>(outb[ao(O_X + 3u * m, f)], outb[ao(O_X + 3u * m + 1u, f)], outb[ao(O_X + 3u * m + 2u, f)]);
    let o = vec3<real>(inp[ai(I_OBS + 3u * m, f)], inp[ai(I_OBS + 3u * m + 1u, f)], inp[ai(I_OBS + 3u * m + 2u, f)]);
    return x - o;
}

// Index of H[i][j] (i ≤ j) in the upper triangle packed column by column.
fn hidx(i: u32, j: u32) -> u32 {
    return O_H + j * (j + 1u) / 2u + i;
}
