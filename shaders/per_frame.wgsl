// The one-invocation-per-frame kernel (after shaders/common.wgsl): each invocation evaluates one
// whole frame, in the order of the CPU reference. Kept beside the cooperative kernel as the
// simpler reference and for side-by-side measurement (`bench-batch --kernel per-frame`).
//
// Scratch is structure-of-arrays: entry `row` of frame `f` lives at `row * params.stride + f`
// (the chunk's frame count rounded up to a workgroup), so that neighbouring invocations touch
// neighbouring words.

fn at(row: u32, f: u32) -> u32 {
    return row * params.stride + f;
}

// y = Φ(p) and J_Φ into scratch, forward kinematics of bodies and markers, model markers into
// the output, and E.
fn forward(f: u32) {
    // Φ.
    for (var j = 0u; j < NY; j += 1u) {
        scr[at(S_Y + j, f)] = mf[F_YOFF + j];
    }
    for (var t = 0u; t < NT; t += 1u) {
        let yj = mu[U_TERM + 3u * t];
        let k = mu[U_TERM + 3u * t + 1u];
        let vd = feval(mu[U_TERM + 3u * t + 2u], inp[ai(I_P + k, f)]);
        scr[at(S_Y + yj, f)] += vd.x;
        scr[at(S_DPHI + t, f)] = vd.y;
    }
    // Bodies in topological order.
    let c = reference(f);
    for (var b = 0u; b < NB; b += 1u) {
        body_frame(b, f, c);
    }
    // Markers and the objective.
    var e = vec3<real>(0.0, 0.0, 0.0);
    for (var m = 0u; m < NM; m += 1u) {
        let x = marker_position(m, f);
        outb[ao(O_X + 3u * m, f)] = x.x;
        outb[ao(O_X + 3u * m + 1u, f)] = x.y;
        outb[ao(O_X + 3u * m + 2u, f)] = x.z;
        e += marker_energy(m, f, x);
    }
    for (var j = 0u; j < NY; j += 1u) {
        e.x += tracking_energy(j, f);
    }
    outb[ao(O_E, f)] = e.x;
    outb[ao(O_SQ, f)] = e.y;
    outb[ao(O_USED, f)] = e.z;
}

// J_m rows of every used marker, H (upper triangle) and g, after `forward`.
fn assemble(f: u32) {
    for (var k = 0u; k < NP; k += 1u) {
        outb[ao(O_G + k, f)] = 0.0;
    }
    for (var k = 0u; k < NH; k += 1u) {
        outb[ao(O_H + k, f)] = 0.0;
    }
    for (var lb = 0u; lb < NLB; lb += 1u) {
        let base = U_LB + 7u * lb;
        let ns = mu[base + 1u];
        let slots = mu[base + 2u];
        var any = false;
        for (var q = mu[base + 5u]; q < mu[base + 6u]; q += 1u) {
            let m = mu[U_LBM + 3u * q];
            let w = inp[ai(I_MW + m, f)];
            if (w <= 0.0) {
                continue;
            }
            if (!any) {
                any = true;
                chain(lb, f, S_AW);
            }
            marker_rows(q, lb, f, S_AW, S_ROW);
            let r = residual(m, f);
            for (var i = 0u; i < ns; i += 1u) {
                let ki = mu[slots + i];
                let ci = w * s3(S_ROW + 3u * i, f);
                outb[ao(O_G + ki, f)] += dot(ci, r);
                for (var j = i; j < ns; j += 1u) {
                    let h = hidx(ki, mu[slots + j]);
                    outb[ao(h, f)] += dot(ci, s3(S_ROW + 3u * j, f));
                }
            }
        }
    }
    // Tracking term J_Φᵀ W_t J_Φ, J_Φᵀ W_t e_t.
    for (var j = 0u; j < NY; j += 1u) {
        let w = tracking_weight(j, f);
        if (w <= 0.0) {
            continue;
        }
        let e = scr[at(S_Y + j, f)] - inp[ai(I_TREF + j, f)];
        let t0 = mu[U_YT + 2u * j];
        let t1 = mu[U_YT + 2u * j + 1u];
        for (var t = t0; t < t1; t += 1u) {
            let kt = mu[U_TERM + 3u * t + 1u];
            let dt = scr[at(S_DPHI + t, f)];
            outb[ao(O_G + kt, f)] += w * dt * e;
            for (var u = t0; u < t1; u += 1u) {
                let ku = mu[U_TERM + 3u * u + 1u];
                if (kt <= ku) {
                    outb[ao(hidx(kt, ku), f)] += w * dt * scr[at(S_DPHI + u, f)];
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn linearize(@builtin(global_invocation_id) gid: vec3<u32>) {
    let f = gid.x;
    if (f >= params.n) {
        return;
    }
    forward(f);
    assemble(f);
}

@compute @workgroup_size(64)
fn energy(@builtin(global_invocation_id) gid: vec3<u32>) {
    let f = gid.x;
    if (f >= params.n) {
        return;
    }
    forward(f);
    outb[4u * f] = outb[ao(O_E, f)];
    outb[4u * f + 1u] = outb[ao(O_SQ, f)];
    outb[4u * f + 2u] = outb[ao(O_USED, f)];
}
