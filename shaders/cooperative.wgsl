// The cooperative kernel (after shaders/common.wgsl): one workgroup of WG invocations evaluates one
// frame. Each phase spreads whole outputs over the invocations — y entries, the bodies of one
// level of the tree, markers, layout bodies' chains, marker entries' Jacobian rows, then entries
// of g and of the upper triangle of H, each summed by one invocation from the gather lists of
// src/kinematics/gpu/gather.rs in the order the per-frame kernel adds them — with a barrier
// between phases. Only E, Σ‖r‖² and the markers used are reduced across invocations (in
// workgroup memory, in a fixed tree order). Nothing is accumulated by two invocations, so results
// are the same run to run.
//
// Scratch is frame-major: the block of frame `f` is `C_ROWS` words at `f * C_ROWS`, so one
// workgroup works in one contiguous block (in cache on a GPU).

const WG: u32 = 64u;

var<workgroup> red: array<vec3<real>, WG>;

fn at(row: u32, f: u32) -> u32 {
    return f * C_ROWS + row;
}

// y = Φ(p) and J_Φ: invocation `lid` takes y entries lid, lid + WG, ...
fn phi(f: u32, lid: u32) {
    for (var j = lid; j < NY; j += WG) {
        var y = mf[F_YOFF + j];
        for (var t = mu[U_YT + 2u * j]; t < mu[U_YT + 2u * j + 1u]; t += 1u) {
            let k = mu[U_TERM + 3u * t + 1u];
            let vd = feval(mu[U_TERM + 3u * t + 2u], inp[ai(I_P + k, f)]);
            y += vd.x;
            scr[at(S_DPHI + t, f)] = vd.y;
        }
        scr[at(S_Y + j, f)] = y;
    }
}

// Φ, bodies level by level, model markers into the output and (E, Σ‖r‖², used) into the output
// block (by invocation 0). Every invocation of the workgroup calls it (it holds barriers).
fn forward(f: u32, lid: u32) {
    phi(f, lid);
    storageBarrier();
    let c = reference(f);
    for (var l = 0u; l < NLEV; l += 1u) {
        for (var i = mu[U_LEV + l] + lid; i < mu[U_LEV + l + 1u]; i += WG) {
            body_frame(mu[U_LEVB + i], f, c);
        }
        storageBarrier();
    }
    var e = vec3<real>(0.0, 0.0, 0.0);
    for (var m = lid; m < NM; m += WG) {
        let x = marker_position(m, f);
        outb[ao(O_X + 3u * m, f)] = x.x;
        outb[ao(O_X + 3u * m + 1u, f)] = x.y;
        outb[ao(O_X + 3u * m + 2u, f)] = x.z;
        e += marker_energy(m, f, x);
    }
    for (var j = lid; j < NY; j += WG) {
        e.x += tracking_energy(j, f);
    }
    red[lid] = e;
    workgroupBarrier();
    for (var s = WG / 2u; s > 0u; s = s / 2u) {
        if (lid < s) {
            red[lid] += red[lid + s];
        }
        workgroupBarrier();
    }
    if (lid == 0u) {
        let t = red[0];
        outb[ao(O_E, f)] = t.x;
        outb[ao(O_SQ, f)] = t.y;
        outb[ao(O_USED, f)] = t.z;
    }
    storageBarrier();
}

// Weight of marker entry q in this frame (0 where unobserved).
fn q_weight(q: u32, f: u32) -> real {
    return inp[ai(I_MW + mu[U_LBM + 3u * q], f)];
}

// Scratch row of slot `s` of marker entry `q`'s Jacobian rows.
fn q_row(q: u32, s: u32) -> u32 {
    return C_ROW + mu[U_Q + 2u * q + 1u] + 3u * s;
}

// J_m rows of every used marker, then g and H (upper triangle) by entry, after `forward`.
fn assemble(f: u32, lid: u32) {
    // Chains of the layout bodies with a used marker.
    for (var lb = lid; lb < NLB; lb += WG) {
        let base = U_LB + 7u * lb;
        var any = false;
        for (var q = mu[base + 5u]; q < mu[base + 6u]; q += 1u) {
            any = any || q_weight(q, f) > 0.0;
        }
        if (any) {
            chain(lb, f, C_AW + mu[U_LBAW + lb]);
        }
    }
    storageBarrier();
    // Rows and (w, r) of every marker entry (w = 0, r = 0 where unused).
    for (var q = lid; q < NQE; q += WG) {
        let w = q_weight(q, f);
        var r = vec3<real>(0.0, 0.0, 0.0);
        var wq: real = 0.0;
        if (w > 0.0) {
            let lb = mu[U_Q + 2u * q];
            marker_rows(q, lb, f, C_AW + mu[U_LBAW + lb], q_row(q, 0u));
            r = residual(mu[U_LBM + 3u * q], f);
            wq = w;
        }
        scr[at(C_WR + 4u * q, f)] = wq;
        put3(C_WR + 4u * q + 1u, f, r);
    }
    storageBarrier();
    // g_k = Σ w (J_q,s)ᵀ r_q + Σ_t w_j ∂Φ_t e_j.
    for (var k = lid; k < NP; k += WG) {
        var g: real = 0.0;
        for (var e = mu[U_GMO + k]; e < mu[U_GMO + k + 1u]; e += 1u) {
            let q = mu[U_GM + 2u * e];
            let w = scr[at(C_WR + 4u * q, f)];
            if (w > 0.0) {
                g += dot(w * s3(q_row(q, mu[U_GM + 2u * e + 1u]), f), s3(C_WR + 4u * q + 1u, f));
            }
        }
        for (var e = mu[U_GTO + k]; e < mu[U_GTO + k + 1u]; e += 1u) {
            let t = mu[U_GT + e];
            let j = mu[U_TERM + 3u * t];
            let w = tracking_weight(j, f);
            if (w > 0.0) {
                g += w * scr[at(S_DPHI + t, f)] * (scr[at(S_Y + j, f)] - inp[ai(I_TREF + j, f)]);
            }
        }
        outb[ao(O_G + k, f)] = g;
    }
    // H_ij = Σ w (J_q,i)ᵀ J_q,j + Σ w_j ∂Φ_t ∂Φ_u, upper triangle by columns.
    for (var h = lid; h < NH; h += WG) {
        var v: real = 0.0;
        for (var e = mu[U_HMO + h]; e < mu[U_HMO + h + 1u]; e += 1u) {
            let q = mu[U_HM + 3u * e];
            let w = scr[at(C_WR + 4u * q, f)];
            if (w > 0.0) {
                v += dot(w * s3(q_row(q, mu[U_HM + 3u * e + 1u]), f), s3(q_row(q, mu[U_HM + 3u * e + 2u]), f));
            }
        }
        for (var e = mu[U_HTO + h]; e < mu[U_HTO + h + 1u]; e += 1u) {
            let t = mu[U_HT + 2u * e];
            let w = tracking_weight(mu[U_TERM + 3u * t], f);
            if (w > 0.0) {
                v += w * scr[at(S_DPHI + t, f)] * scr[at(S_DPHI + mu[U_HT + 2u * e + 1u], f)];
            }
        }
        outb[ao(O_H + h, f)] = v;
    }
}

@compute @workgroup_size(WG)
fn linearize(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let f = wid.x;
    if (f >= params.n) {
        return;
    }
    forward(f, lid);
    assemble(f, lid);
}

@compute @workgroup_size(WG)
fn energy(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let f = wid.x;
    if (f >= params.n) {
        return;
    }
    forward(f, lid);
    if (lid == 0u) {
        outb[4u * f] = outb[ao(O_E, f)];
        outb[4u * f + 1u] = outb[ao(O_SQ, f)];
        outb[4u * f + 2u] = outb[ao(O_USED, f)];
    }
}
