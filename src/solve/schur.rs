//! The Schur complement of calibration's joint solve ([`super::calibrate::JointProblem`]): each
//! frame linearised (its Gauss–Newton blocks over the poses, scales and registered offsets) and
//! its poses eliminated, leaving the dense reduced system over `z = [s; o]`.
//!
//! The poses are ordered leaves first, so that a frame's pose block factors without fill and
//! `U = L⁻¹B` keeps each marker's column zero off the pose proxies that move it (its chain to the
//! root); the triangular solve and `UᵀU` skip those zeros ([`fixed::solve_lower_sparse`],
//! [`fixed::add_t_mul_sym_sparse`]) with the dense products' bits. Frames are linearised and
//! eliminated in parallel in fixed pieces whose sums are added in piece order, so the result
//! does not depend on the thread count (docs/CALIBRATION.md, "The solver").

use super::joint::{JointProblem, JointState};
use super::prior::Globals;
use crate::kinematics::assembly::{EvalWorkspace, Evaluator, FrameProblem};
use crate::model::fixed;
use crate::model::proxy::ProxyKind;
use nalgebra::{DMatrix, DVector, Matrix3, Vector3};

/// Per-frame blocks of the Schur complement: `A = L Lᵀ`, `U = L⁻¹ B`, `w = L⁻¹ g_q`, so that
/// `Bᵀ A⁻¹ B = UᵀU`, `Bᵀ A⁻¹ g_q = Uᵀw` and `Δq = −L⁻ᵀ (w + U Δz)`. Kept across steps (its
/// buffers are overwritten in place: no fresh pages per step).
#[derive(Default)]
pub(super) struct FrameBlocks {
    pub(super) l: DMatrix<f64>,
    pub(super) u: DMatrix<f64>,
    pub(super) w: DVector<f64>,
    /// The damping added to `A`'s diagonal (for the predicted decrease).
    pub(super) damping: DVector<f64>,
    /// False where the damped pose block is not positive definite (the frame's poses stay).
    pub(super) ok: bool,
}

/// One frame's Gauss–Newton blocks at the current state, undamped: the pose block `A` (coordinate
/// targets and markers), the pose gradient and the pose–`z` coupling `B`.
#[derive(Default)]
pub(super) struct FrameLinear {
    pub(super) a: DMatrix<f64>,
    pub(super) gq: DVector<f64>,
    pub(super) b: DMatrix<f64>,
}

/// The whole problem linearised at the current state: kept while Levenberg–Marquardt rejects
/// steps (only the damping changes), rebuilt in place after an accepted one.
#[derive(Default)]
pub(super) struct Linear {
    /// `C + Σ_k C_k` over `z` (priors, and each frame's scale and offset blocks).
    pub(super) c: DMatrix<f64>,
    /// `−g_z`.
    pub(super) neg_gz: DVector<f64>,
    pub(super) frames: Vec<FrameLinear>,
    /// Each piece's partial sums of `c` and `−g_z`.
    pieces: Vec<(DMatrix<f64>, DVector<f64>)>,
}

/// The elimination's buffers, kept across steps: each frame's blocks and each piece's partial
/// sums of the reduced system and of `Σ_k Uᵀw` ([`JointProblem::eliminate`]).
#[derive(Default)]
pub(super) struct Eliminated {
    pub(super) blocks: Vec<FrameBlocks>,
    pieces: Vec<(DMatrix<f64>, DVector<f64>)>,
    /// The reduced system `S = C − Σ_k UᵀU` (undamped) and `Σ_k Uᵀw`.
    pub(super) schur: DMatrix<f64>,
    pub(super) reduced: DVector<f64>,
}

/// `m` resized to `r × c`, its contents unspecified (callers overwrite every entry). Its
/// allocation is kept when large enough, so that a buffer reused across stages and subjects of
/// other shapes touches no fresh pages ([`JointScratch`]).
fn shaped(m: &mut DMatrix<f64>, r: usize, c: usize) -> &mut DMatrix<f64> {
    if m.shape() != (r, c) {
        let mut v: Vec<f64> = std::mem::replace(m, DMatrix::zeros(0, 0)).data.into();
        v.resize(r * c, 0.0);
        *m = DMatrix::from_vec(r, c, v);
    }
    m
}

/// `v` resized to `n`, its contents unspecified, its allocation kept as in [`shaped`].
fn sized(v: &mut DVector<f64>, n: usize) -> &mut DVector<f64> {
    if v.len() != n {
        let mut d: Vec<f64> = std::mem::replace(v, DVector::zeros(0)).data.into();
        d.resize(n, 0.0);
        *v = DVector::from_vec(d);
    }
    v
}

/// The joint solve's buffers ([`Linear`], [`Eliminated`]): a few megabytes per calibration
/// (each frame's `B` and `U`, `frames × poses × (scales + 3 × markers)` values, and the pieces'
/// reduced systems). Kept per thread between calibrations, so that each subject after the first
/// writes into pages already mapped instead of faulting in fresh zeroed ones (about 10 % of the
/// joint stages' time on the synthetic archive, docs/CALIBRATION.md, "Cost").
#[derive(Default)]
pub(super) struct JointScratch {
    pub(super) linear: Linear,
    pub(super) elim: Eliminated,
}

/// Largest scratch kept for the next calibration on a thread (bytes); a larger one (a calibration
/// on thousands of frames) is freed.
const SCRATCH_KEPT_BYTES: usize = 64 << 20;

impl JointScratch {
    /// Bytes held by the buffers (their allocations, which a reshape keeps).
    fn bytes(&self) -> usize {
        let m = |m: &DMatrix<f64>| m.data.as_vec().capacity();
        let v = |v: &DVector<f64>| v.data.as_vec().capacity();
        let pieces = |p: &[(DMatrix<f64>, DVector<f64>)]| p.iter().map(|(a, b)| m(a) + v(b)).sum::<usize>();
        let l = &self.linear;
        let e = &self.elim;
        let values = m(&l.c)
            + v(&l.neg_gz)
            + l.frames.iter().map(|f| m(&f.a) + v(&f.gq) + m(&f.b)).sum::<usize>()
            + pieces(&l.pieces)
            + e.blocks.iter().map(|b| m(&b.l) + m(&b.u) + v(&b.w) + v(&b.damping)).sum::<usize>()
            + pieces(&e.pieces)
            + m(&e.schur)
            + v(&e.reduced);
        values * std::mem::size_of::<f64>()
    }

    /// Runs `f` with this thread's kept scratch (a fresh one when none is kept, or when a
    /// calibration nested on this thread holds it), and keeps it afterwards unless it grew past
    /// [`SCRATCH_KEPT_BYTES`]. Results do not depend on what the buffers held.
    pub(super) fn with<R>(f: impl FnOnce(&mut JointScratch) -> R) -> R {
        thread_local! {
            static KEPT: std::cell::Cell<Option<Box<JointScratch>>> = const { std::cell::Cell::new(None) };
        }
        let mut scratch = KEPT.with(|k| k.take()).unwrap_or_default();
        let out = f(&mut scratch);
        if scratch.bytes() <= SCRATCH_KEPT_BYTES {
            KEPT.with(|k| k.set(Some(scratch)));
        }
        out
    }
}

/// Piece buffers: one `(n × n, n)` pair per piece of `frames` frames, zeroed.
fn zeroed_pieces(p: &mut Vec<(DMatrix<f64>, DVector<f64>)>, frames: usize, n: usize) {
    p.resize_with(frames.div_ceil(ELIMINATION_PIECE), Default::default);
    for (m, v) in p.iter_mut() {
        shaped(m, n, n).as_mut_slice().fill(0.0);
        sized(v, n).fill(0.0);
    }
}

/// Frames per piece of the parallel elimination. Fixed, so that the pieces' partial sums (added
/// in piece order) and hence every bit of the result do not depend on the thread count.
const ELIMINATION_PIECE: usize = 8;

impl JointProblem<'_> {
    pub(super) fn scale_indices(&self) -> (Vec<usize>, Vec<usize>) {
        let np = self.proxy.np();
        let scale = (0..np).filter(|&k| self.proxy.proxies[k].kind == ProxyKind::Scale).collect();
        let mut pose: Vec<usize> = (0..np).filter(|&k| self.proxy.proxies[k].kind != ProxyKind::Scale).collect();
        // Leaves first: each pose proxy after every proxy that moves a body below it, so that
        // a frame's Cholesky factor has no fill and `U = L⁻¹B` keeps each marker's column zero
        // off its chain to the root ([`fixed::solve_lower_sparse`], [`fixed::add_t_mul_sym_sparse`]).
        let depth = self.pose_depths();
        pose.sort_by_key(|&k| std::cmp::Reverse(depth[k]));
        (scale, pose)
    }

    /// Per proxy: the depth in the body tree (bodies on its root chain) of the highest body whose
    /// joint coordinates it drives (`usize::MAX` for a proxy that drives none).
    fn pose_depths(&self) -> Vec<usize> {
        let model = self.model;
        let mut body_of = vec![None; model.nq()];
        for (b, body) in model.bodies.iter().enumerate() {
            for m in body.joint.motions.clone() {
                if let Some(c) = model.motions[m].coordinate {
                    body_of[c] = Some(b);
                }
            }
        }
        let mut depth = vec![usize::MAX; self.proxy.np()];
        for t in &self.proxy.terms {
            if let Some(Some(b)) = body_of.get(t.y_index) {
                depth[t.proxy] = depth[t.proxy].min(model.chain(*b).len());
            }
        }
        depth
    }

    /// The Gauss–Newton blocks of every frame and of the priors at `state`, into `out` (its
    /// buffers reused).
    pub(super) fn linearize(
        &self,
        state: &JointState,
        (scale, pose): (&[usize], &[usize]),
        cols: &[Option<usize>],
        nz: usize,
        out: &mut Linear,
    ) {
        let nq = pose.len();
        let model = self.model_with(&state.offsets);
        let eval = Evaluator::new(&model, self.proxy);
        let Linear { c, neg_gz, frames, pieces } = out;
        shaped(c, nz, nz).as_mut_slice().fill(0.0);
        sized(neg_gz, nz).fill(0.0);
        {
            let g = Globals { p: &state.poses[0], scale, offsets: &state.offsets, offset_col: cols };
            let mut gz = DVector::zeros(nz);
            for t in self.terms {
                t.add(&g, Some((&mut *c, &mut gz)));
            }
            *neg_gz -= gz;
        }
        // Frames in pieces of [`ELIMINATION_PIECE`] in parallel, each piece with its own
        // workspace and partial sums, added in piece order (the same bits whatever the threads).
        use rayon::prelude::*;
        let registered = cols.iter().any(Option::is_some);
        // Each proxy's row among the poses and column among the scales.
        let mut pose_row = vec![None; self.proxy.np()];
        let mut scale_col = vec![None; self.proxy.np()];
        pose.iter().enumerate().for_each(|(i, &k)| pose_row[k] = Some(i));
        scale.iter().enumerate().for_each(|(i, &k)| scale_col[k] = Some(i));
        let idx: Vec<usize> = (0..self.frames.len()).collect();
        frames.resize_with(self.frames.len(), Default::default);
        zeroed_pieces(pieces, self.frames.len(), nz);
        idx.par_chunks(ELIMINATION_PIECE)
            .zip(frames.par_chunks_mut(ELIMINATION_PIECE))
            .zip(pieces.par_iter_mut())
            .for_each(|((piece, piece_frames), (c, neg_gz))| {
                let mut ws = EvalWorkspace::new(&model, self.proxy);
                for (&k, f) in piece.iter().zip(piece_frames) {
                    let (obs, p, mw) = (self.frames[k], &state.poses[k], self.weights[k]);
                    // The frame's Gauss–Newton model over all proxies (markers and coordinate
                    // targets, per body as the frame solver forms it): `A`, `g_q`, and the scale
                    // columns of `B`, `C` and `g_z`.
                    let fp = FrameProblem {
                        observed: obs,
                        marker_weights: mw,
                        tracking_ref: self.tracking_refs[k],
                        tracking_weights: self.tracking_weights[k],
                    };
                    eval.linearize(p, &fp, &mut ws);
                    let h = &ws.gn.h;
                    let (hs, np) = (h.as_slice(), h.nrows());
                    let FrameLinear { a, gq, b } = f;
                    let a = shaped(a, nq, nq);
                    for (col, &kj) in a.as_mut_slice().chunks_exact_mut(nq).zip(pose) {
                        let hj = &hs[kj * np..(kj + 1) * np];
                        for (v, &ki) in col.iter_mut().zip(pose) {
                            *v = hj[ki];
                        }
                    }
                    for (v, &k) in sized(gq, nq).iter_mut().zip(pose) {
                        *v = ws.gn.g[k];
                    }
                    let b = shaped(b, nq, nz);
                    b.as_mut_slice().fill(0.0);
                    for (c_, &ks) in scale.iter().enumerate() {
                        for (r_, &kq) in pose.iter().enumerate() {
                            b[(r_, c_)] = h[(kq, ks)];
                        }
                        for (r_, &kr) in scale.iter().enumerate() {
                            c[(r_, c_)] += h[(kr.min(ks), kr.max(ks))];
                        }
                        neg_gz[c_] -= ws.gn.g[ks];
                    }
                    // Offset parts: marker m's rows depend on its own offset through
                    // `J_o = R_b diag(s_b)`, a 3 × 3 block per marker: `B`'s columns `w J_qᵀ J_o`,
                    // `C`'s `w J_sᵀ J_o` and `w J_oᵀ J_o`, and `g_o = w J_oᵀ r`.
                    if registered {
                        eval.marker_rows(&fp, &mut ws, |m, proxies, rows, kin, y| {
                            let Some(col) = cols[m] else { return };
                            let w = mw[m];
                            let bdy = model.markers[m].body;
                            let sb = Vector3::from_fn(|ax, _| y[model.scale_index(bdy, ax)]);
                            let jo: Matrix3<f64> = kin.body_rot[bdy] * Matrix3::from_diagonal(&sb);
                            for (slot, &k) in proxies.iter().enumerate() {
                                let jr = Vector3::new(rows[3 * slot], rows[3 * slot + 1], rows[3 * slot + 2]);
                                let v = jo.tr_mul(&jr) * w;
                                if let Some(q) = pose_row[k] {
                                    for ax in 0..3 {
                                        b[(q, col + ax)] = v[ax];
                                    }
                                } else if let Some(sc) = scale_col[k] {
                                    for ax in 0..3 {
                                        c[(sc, col + ax)] += v[ax];
                                        c[(col + ax, sc)] += v[ax];
                                    }
                                }
                            }
                            let joo = jo.tr_mul(&jo) * w;
                            let row = 3 * m;
                            let r_m = Vector3::from_fn(|ax, _| kin.markers[row + ax] - obs[row + ax]);
                            let g_o = jo.tr_mul(&r_m) * w;
                            for ax in 0..3 {
                                for bb in 0..3 {
                                    c[(col + ax, col + bb)] += joo[(ax, bb)];
                                }
                                neg_gz[col + ax] -= g_o[ax];
                            }
                        });
                    }
                    // Poses at an end of their range that the gradient pushes beyond it stay there: the
                    // step would be clipped, and the rest of the frame's step, computed as if it were
                    // not, would then not be the model's minimiser (steps rejected one after another).
                    for (i, &k) in pose.iter().enumerate() {
                        let (lo, hi) = self.proxy.proxies[k].range;
                        let tol = 1e-9 * (hi - lo).abs().max(1.0);
                        if (p[k] <= lo + tol && gq[i] > 0.0) || (p[k] >= hi - tol && gq[i] < 0.0) {
                            a.row_mut(i).fill(0.0);
                            a.column_mut(i).fill(0.0);
                            a[(i, i)] = 1.0;
                            gq[i] = 0.0;
                            b.row_mut(i).fill(0.0);
                        }
                    }
                }
            });
        for (pc, pg) in pieces.iter() {
            *c += pc;
            *neg_gz += pg;
        }
    }

    /// Eliminates every frame's poses at damping `lambda`: the reduced system
    /// `S = C − Σ_k UᵀU` (undamped in `z`) and `Σ_k Uᵀw` into `out.schur` and `out.reduced`, each
    /// frame's blocks into `out.blocks` (buffers reused; `ok` false where the damped pose block is
    /// not positive definite). Frames are eliminated in pieces of [`ELIMINATION_PIECE`] in
    /// parallel, the pieces' sums added in order.
    pub(super) fn eliminate(&self, lin: &Linear, lambda: f64, out: &mut Eliminated) {
        use rayon::prelude::*;
        let nz = lin.c.nrows();
        let floor = self.settings.damping_floor;
        let Eliminated { blocks, pieces, schur, reduced } = out;
        blocks.resize_with(lin.frames.len(), Default::default);
        zeroed_pieces(pieces, lin.frames.len(), nz);
        lin.frames
            .par_chunks(ELIMINATION_PIECE)
            .zip(blocks.par_chunks_mut(ELIMINATION_PIECE))
            .zip(pieces.par_iter_mut())
            .for_each(|((piece, piece_blocks), (s, reduced))| {
                let mut scratch = fixed::SparseScratch::default();
                for (f, fb) in piece.iter().zip(piece_blocks) {
                    let nq = f.a.nrows();
                    let mut a = f.a.clone();
                    let damping = sized(&mut fb.damping, nq);
                    for d in 0..nq {
                        damping[d] = lambda * a[(d, d)].max(floor);
                        a[(d, d)] += damping[d];
                    }
                    let Some(chol) = a.cholesky() else {
                        fb.ok = false;
                        continue;
                    };
                    fb.ok = true;
                    fb.l = chol.unpack();
                    shaped(&mut fb.u, nq, nz).as_mut_slice().copy_from_slice(f.b.as_slice());
                    fixed::solve_lower_sparse_in(&fb.l, &mut fb.u, &mut scratch);
                    sized(&mut fb.w, nq).as_mut_slice().copy_from_slice(f.gq.as_slice());
                    fb.l.solve_lower_triangular_unchecked_mut(&mut fb.w);
                    fixed::add_t_mul_sym_sparse(s, -1.0, &fb.u);

                    *reduced += fixed::t_mul_v(&fb.u, &fb.w);
                }
            });
        shaped(schur, nz, nz).copy_from(&lin.c);
        sized(reduced, nz).fill(0.0);
        for (s, r) in pieces.iter() {
            *schur += s;
            *reduced += r;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reshaped_buffer_keeps_its_allocation() {
        // Registration's `B` (poses × (scales + 3 × markers)) after the scale stage's narrower one.
        let mut m = DMatrix::<f64>::zeros(30, 175);
        let at = m.as_ptr();
        shaped(&mut m, 30, 16);
        assert_eq!(m.shape(), (30, 16));
        shaped(&mut m, 30, 175).fill(1.0);
        assert_eq!((m.shape(), m.as_ptr()), ((30, 175), at));
        let mut v = DVector::<f64>::zeros(175);
        let at = v.as_ptr();
        sized(&mut v, 16);
        sized(&mut v, 175);
        assert_eq!((v.len(), v.as_ptr()), (175, at));
    }

    #[test]
    fn a_thread_keeps_its_joint_buffers_up_to_the_limit() {
        std::thread::spawn(|| {
            let at = JointScratch::with(|s| shaped(&mut s.elim.schur, 175, 175).as_ptr());
            assert_eq!(JointScratch::with(|s| s.elim.schur.as_ptr()), at, "not kept");
            // A scratch past the limit (a calibration on thousands of frames) is freed.
            JointScratch::with(|s| {
                shaped(&mut s.elim.schur, 3000, 3000);
            });
            assert_eq!(JointScratch::with(|s| s.elim.schur.len()), 0, "kept past the limit");
        })
        .join()
        .unwrap();
    }
}
