//! The host side of a chunk, without intermediate copies: frames are packed frame-major straight
//! into the mapped upload buffer, and each frame's results are handed to its [`GnSink`] as views
//! into the mapped read-back buffer. Both run on rayon's pool in a few contiguous pieces and
//! return the CPU time they took (seconds, summed over threads, the device's threads excluded).
//!
//! Per-frame layouts (`pack::Rows`): input block of `rows.input` words at `frame · rows.input`;
//! output block of `rows.output` words at `frame · rows.output` of the read-back copy.

use super::pack::Rows;
use super::words::Word;
use crate::kinematics::assembly::FrameProblem;
use crate::kinematics::backend::{EnergyEval, GnSink, GnView, HessianView};
use rayon::prelude::*;

/// CPU time of the calling thread (s).
pub(super) fn thread_cpu_s() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid timespec to write to; the clock id is a constant Linux offers.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return 0.0;
    }
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

/// Runs `f` and returns the CPU time of this thread it took (s).
fn cpu<R>(f: impl FnOnce() -> R) -> (R, f64) {
    let t = thread_cpu_s();
    let r = f();
    (r, thread_cpu_s() - t)
}

/// What packing a chunk needs besides its frames.
pub(super) struct PackJob<'a, 'f> {
    pub rows: Rows,
    pub np: usize,
    pub nm: usize,
    /// The buffers' capacity in frames: the tracking-weight sets start at `cap · rows.input`
    /// words (the shader's `CAP * IN_ROWS`).
    pub cap: usize,
    pub frames: &'a [FrameProblem<'f>],
    pub proxies: &'a [f64],
}

/// The tracking-weight sets of a chunk: frames whose `tracking_weights` are the same slice
/// (one trial's weights, shared by its lanes) share one set of `ny` words, so that a frame's
/// block carries one index instead of `ny` weights. Kept by the backend between chunks (no
/// allocation once warm).
#[derive(Clone, Debug, Default)]
pub(super) struct WeightSets {
    /// Each set's slice, as (address, length), met in frame order.
    index: std::collections::HashMap<(usize, usize), u32>,
    /// The first frame of each set (its weights are that frame's).
    first: Vec<usize>,
    /// Set of each frame of the chunk.
    of_frame: Vec<u32>,
    /// One set's words while converting (u64 storage, aligned for both word sizes).
    words: Vec<u64>,
}

impl WeightSets {
    /// Assigns every frame of `frames` its set; returns the number of sets.
    fn assign(&mut self, frames: &[FrameProblem<'_>]) -> usize {
        self.index.clear();
        self.first.clear();
        self.of_frame.clear();
        let mut last: Option<((usize, usize), u32)> = None;
        for (i, fr) in frames.iter().enumerate() {
            let key = (fr.tracking_weights.as_ptr() as usize, fr.tracking_weights.len());
            let k = match last {
                Some((lk, k)) if lk == key => k,
                _ => {
                    let next = self.first.len() as u32;
                    let k = *self.index.entry(key).or_insert(next);
                    if k == next {
                        self.first.push(i);
                    }
                    k
                }
            };
            last = Some((key, k));
            self.of_frame.push(k);
        }
        self.first.len()
    }
}

/// One frame's input block into `w` (length `rows.input`), with `mask` (length nm) as scratch;
/// returns its reference point: the centroid of the observed and weighted markers, rounded to
/// f32 (exact in both precisions). Unobserved markers get weight and offset 0.
fn pack_frame<W: Word>(job: &PackJob<'_, '_>, i: usize, set: u32, w: &mut [W], mask: &mut [bool]) -> [f64; 3] {
    let (r, fr, nm, np) = (&job.rows, &job.frames[i], job.nm, job.np);
    let (obs, mw) = (&fr.observed[..3 * nm], &fr.marker_weights[..nm]);
    let (mut sum, mut n) = ([0.0f64; 3], 0usize);
    for ((u, o), &wt) in mask.iter_mut().zip(obs.chunks_exact(3)).zip(mw) {
        *u = wt > 0.0 && !(o[0].is_nan() | o[1].is_nan() | o[2].is_nan());
        if *u {
            sum[0] += o[0];
            sum[1] += o[1];
            sum[2] += o[2];
            n += 1;
        }
    }
    let c = sum.map(|s| if n > 0 { (s / n as f64) as f32 as f64 } else { 0.0 });
    for (o, &p) in w[r.i_p..r.i_p + np].iter_mut().zip(&job.proxies[i * np..(i + 1) * np]) {
        *o = W::of(p);
    }
    let (wo, wm) = w[r.i_obs..r.i_tref].split_at_mut(3 * nm);
    for (((d, o), m), (&u, &wt)) in
        wo.chunks_exact_mut(3).zip(obs.chunks_exact(3)).zip(wm.iter_mut()).zip(mask.iter().zip(mw))
    {
        if u {
            d[0] = W::of(o[0] - c[0]);
            d[1] = W::of(o[1] - c[1]);
            d[2] = W::of(o[2] - c[2]);
            *m = W::of(wt);
        } else {
            d.fill(W::of(0.0));
            *m = W::of(0.0);
        }
    }
    convert_padded(&mut w[r.i_tref..r.i_tw], fr.tracking_ref);
    w[r.i_tw] = W::of(set as f64);
    for a in 0..3 {
        w[r.i_c + a] = W::of(c[a]);
    }
    c
}

/// `v` converted into `d`, zeros after it (`d` as long as `y`).
fn convert_padded<W: Word>(d: &mut [W], v: &[f64]) {
    let m = v.len().min(d.len());
    for (o, &x) in d[..m].iter_mut().zip(&v[..m]) {
        *o = W::of(x);
    }
    d[m..].fill(W::of(0.0));
}

/// Packs `job` into `dst` (the mapped upload buffer: the frames' blocks from word 0, their
/// tracking-weight sets from word `cap · rows.input`) and the frames' reference points into
/// `refs`, in `scratch.len()` pieces. Returns the CPU time (s) and the number of weight sets.
pub(super) fn pack<W: Word>(
    job: &PackJob<'_, '_>,
    mut dst: wgpu::WriteOnly<'_, [u8]>,
    refs: &mut [[f64; 3]],
    scratch: &mut [PackScratch],
    sets: &mut WeightSets,
) -> (f64, usize) {
    let n = job.frames.len();
    let per = n.div_ceil(scratch.len().max(1)).max(1);
    let word = std::mem::size_of::<W>();
    let block = job.rows.input * word;
    let ny = job.rows.ny;
    // The sets, on this thread: usually one per trial in the chunk.
    let (k, sets_cpu) = cpu(|| {
        let k = sets.assign(job.frames);
        let table = job.cap * block;
        assert!(n <= job.cap && dst.len() >= table + k * ny * word, "the upload range holds the chunk and its sets");
        sets.words.resize((ny * word).div_ceil(8).max(1), 0);
        for (s, &f) in sets.first.iter().enumerate() {
            let w: &mut [W] = &mut bytemuck::cast_slice_mut::<u64, W>(&mut sets.words)[..ny];
            convert_padded(w, job.frames[f].tracking_weights);
            let at = table + s * ny * word;
            dst.slice(at..at + ny * word).copy_from_slice(bytemuck::cast_slice(w));
        }
        k
    });
    // `WriteOnly<[u8]>` is not `Send`; the pieces write disjoint ranges through its pointer.
    let base = Dst(dst.as_raw_element_ptr());
    let base = &base;
    let refs = &mut refs[..n];
    let of_frame = &sets.of_frame;
    let pieces: f64 = refs
        .par_chunks_mut(per)
        .zip(scratch.par_iter_mut())
        .enumerate()
        .map(|(k, (r, s))| {
            cpu(|| {
                s.words.resize(job.rows.input.div_ceil(8 / std::mem::size_of::<W>()).max(1), 0);
                s.mask.resize(job.nm, false);
                let w: &mut [W] = &mut bytemuck::cast_slice_mut::<u64, W>(&mut s.words)[..job.rows.input];
                let mask = &mut s.mask[..];
                for (j, c) in r.iter_mut().enumerate() {
                    let i = k * per + j;
                    *c = pack_frame(job, i, of_frame[i], w, mask);
                    let bytes: &[u8] = bytemuck::cast_slice(w);
                    // SAFETY: frame i's block `[i·block, (i+1)·block)` lies inside the mapped range
                    // (asserted above), is written by this piece only, and is never read.
                    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), base.0.as_ptr().add(i * block), block) };
                }
            })
            .1
        })
        .sum();
    (sets_cpu + pieces, k)
}

/// One packing piece's scratch: a frame's block (u64 storage, aligned for both word sizes) and
/// its markers' used flags.
#[derive(Clone, Debug, Default)]
pub(super) struct PackScratch {
    words: Vec<u64>,
    mask: Vec<bool>,
}

/// The start of the mapped upload range, shared by the packing pieces.
struct Dst(std::ptr::NonNull<u8>);
// SAFETY: the pieces write disjoint byte ranges and nothing reads them while they run.
unsafe impl Send for Dst {}
unsafe impl Sync for Dst {}

/// Hands frame `i`'s results (block `words[i · rows.output..]`, reference point `refs[i]`) to
/// `sinks[i]`, in pieces of `per` frames. Returns the CPU time (s).
pub(super) fn hand_out<W: Word>(
    words: &[W],
    rows: Rows,
    np: usize,
    refs: &[[f64; 3]],
    sinks: &mut [&mut dyn GnSink],
    per: usize,
) -> f64 {
    let nh = np * (np + 1) / 2;
    sinks
        .par_chunks_mut(per.max(1))
        .enumerate()
        .map(|(k, chunk)| {
            cpu(|| {
                for (j, s) in chunk.iter_mut().enumerate() {
                    let i = k * per.max(1) + j;
                    let b = &words[i * rows.output..(i + 1) * rows.output];
                    s.take(&GnView {
                        energy: b[0].to_f64(),
                        marker_sq_sum: b[1].to_f64(),
                        markers_used: b[2].to_f64() as usize,
                        g: W::reals(&b[rows.o_g..rows.o_g + np]),
                        h: HessianView::UpperColumns(W::reals(&b[rows.o_h..rows.o_h + nh])),
                        markers: W::reals(&b[rows.o_x..]),
                        reference: refs[i],
                    });
                }
            })
            .1
        })
        .sum()
}

/// Energies of a chunk from the compact `(E, Σ‖r‖², used, ·)` rows at `words[4 · i..]`.
pub(super) fn energies<W: Word>(words: &[W], out: &mut [EnergyEval]) {
    for (i, o) in out.iter_mut().enumerate() {
        *o = EnergyEval {
            energy: words[4 * i].to_f64(),
            marker_sq_sum: words[4 * i + 1].to_f64(),
            markers_used: words[4 * i + 2].to_f64() as usize,
        };
    }
}

/// The host path alone, without a device: `frames` packed into plain memory laid out as the
/// upload buffer, then a plain (zeroed) block per frame laid out as the read-back buffer handed
/// to `sinks`, exactly as a chunk's are (each once untimed first, as the persistent buffers are
/// warm). Returns the CPU time of packing and of the hand-out (s,
/// summed over threads). On lavapipe the device's threads share the host's cores and inflate
/// the in-place figures; this is what the host costs when nothing else runs.
pub(super) fn host_path_alone<W: Word>(
    job: &PackJob<'_, '_>,
    sinks: &mut [&mut dyn GnSink],
    pieces: usize,
) -> (f64, f64) {
    let n = job.frames.len();
    let words = job.cap * (job.rows.input + job.rows.ny);
    let mut upload = vec![0u64; (words * std::mem::size_of::<W>()).div_ceil(8)];
    let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut upload);
    let mut refs = vec![[0.0; 3]; n];
    let mut scratch = vec![PackScratch::default(); pieces.max(1)];
    let mut sets = WeightSets::default();
    // Once to fault the pages in (the mapped buffers are persistent), then timed.
    pack::<W>(job, (&mut *bytes).into(), &mut refs, &mut scratch, &mut sets);
    let (pack_s, _) = pack::<W>(job, bytes.into(), &mut refs, &mut scratch, &mut sets);
    let out = vec![W::of(0.0); n * job.rows.output];
    let per = n.div_ceil(pieces.max(1));
    hand_out::<W>(&out, job.rows, job.np, &refs, sinks, per);
    let hand_out_s = hand_out::<W>(&out, job.rows, job.np, &refs, sinks, per);
    (pack_s, hand_out_s)
}
