//! The wgpu compute backend: `shaders/batch.wgsl` evaluates one frame per invocation, in f32 or,
//! where the adapter offers `SHADER_F64` and it is asked for, in f64 ([`Precision`]).
//!
//! The model is uploaded once ([`pack`]); each batch is cut into chunks of at most `cap` frames
//! (what one storage binding holds, from the adapter's limits), each chunk is packed as
//! structure-of-arrays, dispatched, and read back. Positions travel relative to a per-frame
//! reference point (the centroid of the observed markers, rounded to f32) so that f32 resolves
//! body-scale differences rather than lab coordinates.

mod adapter;
pub mod pack;
mod shader;
mod words;

use adapter::best_adapter;
pub use adapter::{list_adapters, searched_backends, AdapterSummary};
pub use shader::{shader_source, Precision, REAL_F32, REAL_F64, SHADER};

use super::assembly::{Evaluator, FrameProblem};
use super::backend::{check_shape, BackendError, BatchBackend, EnergyEval, FrameModel};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Frames per chunk when the adapter's limits allow it. One invocation evaluates one frame, so a
/// large GPU needs many frames per dispatch to be busy (an H100 keeps ~270k invocations resident);
/// device memory is about 27 KB per frame of capacity on the shipped model (input, scratch,
/// output and two read-back buffers).
pub const DEFAULT_CAP: usize = 32_768;

/// Where the backend's wall time went, summed over the calls since the last
/// [`WgpuBackend::reset_phase_times`] (seconds). Chunks overlap (the device runs one chunk while
/// the host packs the next), so `wait_s` is the time the host had nothing else to do.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct PhaseTimes {
    /// Host: reference points and structure-of-arrays packing of the inputs.
    pub pack_s: f64,
    /// Host: queue writes (upload), encoding and submission.
    pub submit_s: f64,
    /// Waiting for the device and for the read-back mapping.
    pub wait_s: f64,
    /// Host: copying the mapped results out.
    pub read_s: f64,
    /// Host: unpacking `(H, g, E, x̂)` into the per-frame results.
    pub unpack_s: f64,
    /// Frames evaluated.
    pub frames: u64,
}

/// Device errors raised outside an error scope, kept until the next check.
type ErrorSlot = Arc<Mutex<Option<String>>>;

/// Batched evaluation on a wgpu adapter (f32 or f64).
pub struct WgpuBackend {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: AdapterSummary,
    linearize: wgpu::ComputePipeline,
    energy: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    input: wgpu::Buffer,
    output: wgpu::Buffer,
    /// Two read-back buffers: one chunk is read while the next one runs.
    staging: [wgpu::Buffer; 2],
    params: wgpu::Buffer,
    rows: pack::Rows,
    cap: usize,
    np: usize,
    nm: usize,
    precision: Precision,
    host_in: words::Words,
    host_out: words::Words,
    /// Reference point of each frame of the two chunks in flight (f32-representable, in f64).
    refs: [Vec<[f64; 3]>; 2],
    errors: ErrorSlot,
    phases: PhaseTimes,
}

impl std::fmt::Debug for WgpuBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WgpuBackend").field("adapter", &self.adapter).field("cap", &self.cap).finish()
    }
}

impl WgpuBackend {
    /// Uploads `eval`'s model to the best adapter found, f32 shaders.
    pub fn new(eval: &Evaluator<'_>, max_cap: usize) -> Result<WgpuBackend, BackendError> {
        WgpuBackend::with_precision(eval, max_cap, Precision::F32)
    }

    /// As [`WgpuBackend::new`], in the given precision (f64 needs an adapter offering
    /// `SHADER_F64`: an error names the adapters found otherwise).
    pub fn with_precision(
        eval: &Evaluator<'_>,
        max_cap: usize,
        precision: Precision,
    ) -> Result<WgpuBackend, BackendError> {
        let adapter = best_adapter(precision)?;
        WgpuBackend::on_adapter(eval, adapter, max_cap, precision)
    }

    /// Where the wall time of the calls since the last reset went.
    pub fn phase_times(&self) -> PhaseTimes {
        self.phases
    }

    /// Starts a new [`PhaseTimes`] account.
    pub fn reset_phase_times(&mut self) {
        self.phases = PhaseTimes::default();
    }

    /// The scalar type the shaders compute in.
    pub fn precision(&self) -> Precision {
        self.precision
    }

    /// The adapter this backend runs on.
    pub fn adapter(&self) -> &AdapterSummary {
        &self.adapter
    }

    /// Frames per dispatch.
    pub fn chunk_capacity(&self) -> usize {
        self.cap
    }

    fn on_adapter(
        eval: &Evaluator<'_>,
        adapter: wgpu::Adapter,
        max_cap: usize,
        precision: Precision,
    ) -> Result<WgpuBackend, BackendError> {
        let summary = AdapterSummary::of(&adapter.get_info());
        let fail = |message: String| BackendError::Device { adapter: summary.name.clone(), message };
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("smocap"),
            required_features: match precision {
                Precision::F32 => wgpu::Features::empty(),
                Precision::F64 => wgpu::Features::SHADER_F64,
            },
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| fail(format!("requesting a device: {e}")))?;
        let errors: ErrorSlot = Arc::default();
        let slot = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let mut s = slot.lock().unwrap_or_else(|p| p.into_inner());
            s.get_or_insert_with(|| e.to_string());
        }));

        let packed = pack::pack(eval.model, eval.proxy, &eval.layout);
        let rows = packed.rows;
        // Chunk capacity: every per-frame buffer must fit one binding.
        let word = match precision {
            Precision::F32 => 4,
            Precision::F64 => 8,
        };
        let widest = word * rows.input.max(rows.scratch).max(rows.output) as u64;
        let bind = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        let by_limits = (bind / widest) as usize;
        let by_groups = limits.max_compute_workgroups_per_dimension as usize * 64;
        let cap = max_cap.min(by_limits).min(by_groups) / 64 * 64;
        if cap == 0 {
            return Err(fail(format!(
                "one frame needs {widest} bytes per binding, more than the adapter's limit of {bind} bytes"
            )));
        }
        let source = shader_source(&packed, cap, precision);

        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("batch.wgsl"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let storage = |binding: u32, read_only: bool| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("batch"),
            entries: &[
                storage(0, true),
                storage(1, true),
                storage(2, true),
                storage(3, false),
                storage(4, false),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("batch"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let linearize = pipeline("linearize");
        let energy = pipeline("energy");

        use wgpu::util::DeviceExt as _;
        let init = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let mu = init("model u32", bytemuck::cast_slice(&packed.mu));
        let mf = init("model reals", words::Words::from_f64(precision, &packed.mf).bytes(packed.mf.len()));
        let buffer = |label: &str, words: usize, usage: wgpu::BufferUsages| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: word * words as u64,
                usage,
                mapped_at_creation: false,
            })
        };
        use wgpu::BufferUsages as U;
        let input = buffer("input", cap * rows.input, U::STORAGE | U::COPY_DST);
        let scratch = buffer("scratch", cap * rows.scratch, U::STORAGE);
        let output = buffer("output", cap * rows.output, U::STORAGE | U::COPY_SRC);
        let staging = [0, 1].map(|_| buffer("staging", cap * rows.output, U::MAP_READ | U::COPY_DST));
        // Four u32: whatever the precision, 16 bytes.
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("params"),
            size: 16,
            usage: U::UNIFORM | U::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("batch"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: mu.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: mf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: input.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: scratch.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: output.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 5, resource: params.as_entire_binding() },
            ],
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(fail(format!("creating the compute pipelines: {e}")));
        }
        Ok(WgpuBackend {
            device,
            queue,
            adapter: summary,
            linearize,
            energy,
            bind_group,
            input,
            output,
            staging,
            params,
            rows,
            cap,
            np: eval.proxy.np(),
            nm: eval.model.markers.len(),
            precision,
            host_in: words::Words::new(precision),
            host_out: words::Words::new(precision),
            refs: [vec![[0.0; 3]; cap], vec![[0.0; 3]; cap]],
            errors,
            phases: PhaseTimes::default(),
        })
    }

    fn fail(&self, message: String) -> BackendError {
        BackendError::Device { adapter: self.adapter.name.clone(), message }
    }

    /// Packs frames into `host_in` (structure of arrays, stride [`stride`]): first each frame's
    /// reference point, then row by row in parallel, so that every row is written contiguously.
    fn pack_chunk(&mut self, frames: &[FrameProblem<'_>], proxies: &[f64], slot: usize) {
        let (cap, r, np, nm) = (stride(frames.len()), self.rows, self.np, self.nm);
        let used = |fr: &FrameProblem<'_>, m: usize| {
            fr.marker_weights[m] > 0.0 && !fr.observed[3 * m..3 * m + 3].iter().any(|v| v.is_nan())
        };
        // Reference point: the centroid of the observed markers, rounded to f32 (exact in both
        // precisions).
        let refs = &mut self.refs[slot];
        refs[..frames.len()].par_iter_mut().zip(frames).for_each(|(c, fr)| {
            let (mut sum, mut n) = ([0.0f64; 3], 0usize);
            for m in (0..nm).filter(|&m| used(fr, m)) {
                for (a, s) in sum.iter_mut().enumerate() {
                    *s += fr.observed[3 * m + a];
                }
                n += 1;
            }
            *c = sum.map(|s| if n > 0 { (s / n as f64) as f32 as f64 } else { 0.0 });
        });
        let refs = &self.refs[slot];
        self.host_in.ensure(cap * r.input);
        self.host_in.fill_rows(r.input, cap, frames.len(), |row, i| {
            let fr = &frames[i];
            if row < r.i_obs {
                proxies[i * np + row - r.i_p]
            } else if row < r.i_mw {
                let (m, a) = ((row - r.i_obs) / 3, (row - r.i_obs) % 3);
                if used(fr, m) {
                    fr.observed[3 * m + a] - refs[i][a]
                } else {
                    0.0
                }
            } else if row < r.i_tref {
                let m = row - r.i_mw;
                if used(fr, m) {
                    fr.marker_weights[m]
                } else {
                    0.0
                }
            } else if row < r.i_tw {
                fr.tracking_ref.get(row - r.i_tref).copied().unwrap_or(0.0)
            } else if row < r.i_c {
                fr.tracking_weights.get(row - r.i_tw).copied().unwrap_or(0.0)
            } else {
                refs[i][row - r.i_c]
            }
        });
    }

    /// Uploads the packed chunk of `n` frames, dispatches it and starts reading back its first
    /// `rows` output rows into staging buffer `slot`.
    fn submit(&mut self, slot: usize, n: usize, linearize: bool) -> Pending {
        let rows = if linearize { self.rows.output } else { 3 };
        let st = stride(n);
        // Queue writes are ordered after earlier submissions, so the chunk in flight keeps its data.
        self.queue.write_buffer(&self.input, 0, self.host_in.bytes(st * self.rows.input));
        self.queue.write_buffer(&self.params, 0, bytemuck::cast_slice(&[n as u32, st as u32, 0, 0]));
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("chunk") });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(if linearize { &self.linearize } else { &self.energy });
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(n.div_ceil(64) as u32, 1, 1);
        }
        let bytes = (self.host_in.word() * rows * st) as u64;
        enc.copy_buffer_to_buffer(&self.output, 0, &self.staging[slot], 0, bytes);
        let index = self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        self.staging[slot].slice(..bytes).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        Pending { slot, rows, stride: st, index, rx }
    }

    /// Waits for a submitted chunk and copies its results into `host_out`.
    fn finish(&mut self, p: Pending) -> Result<(), BackendError> {
        let t = Instant::now();
        self.device
            .poll(wgpu::PollType::Wait { submission_index: Some(p.index), timeout: None })
            .map_err(|e| self.fail(format!("waiting for the device: {e}")))?;
        match p.rx.recv() {
            Ok(Ok(())) => {}
            Ok(Err(e)) => return Err(self.fail(format!("mapping the results: {e}"))),
            Err(_) => return Err(self.fail("the results were never mapped".into())),
        }
        self.phases.wait_s += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let words = p.rows * p.stride;
        {
            let slice = self.staging[p.slot].slice(..(self.host_out.word() * words) as u64);
            let view = slice.get_mapped_range().map_err(|e| self.fail(format!("reading the results: {e:?}")))?;
            self.host_out.copy_from_bytes(&view);
        }
        self.staging[p.slot].unmap();
        self.phases.read_s += t.elapsed().as_secs_f64();
        if let Some(e) = self.errors.lock().unwrap_or_else(|p| p.into_inner()).take() {
            return Err(self.fail(e));
        }
        Ok(())
    }

    /// Runs `frames` chunk by chunk, two chunks in flight: while the device works on chunk
    /// `i`, the host packs chunk `i + 1` and unpacks chunk `i − 1` with `unpack(range, self)`.
    fn run(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        linearize: bool,
        mut unpack: impl FnMut(std::ops::Range<usize>, &WgpuBackend, usize, usize),
    ) -> Result<(), BackendError> {
        let (n, cap, np) = (frames.len(), self.cap, self.np);
        let mut in_flight: Option<(Pending, std::ops::Range<usize>)> = None;
        for c in 0..n.div_ceil(cap) {
            let (a, b) = (c * cap, ((c + 1) * cap).min(n));
            let slot = c % 2;
            let t = Instant::now();
            self.pack_chunk(&frames[a..b], &proxies[a * np..b * np], slot);
            self.phases.pack_s += t.elapsed().as_secs_f64();
            let t = Instant::now();
            let pending = self.submit(slot, b - a, linearize);
            self.phases.submit_s += t.elapsed().as_secs_f64();
            if let Some((p, range)) = in_flight.replace((pending, a..b)) {
                let (s, st) = (p.slot, p.stride);
                self.finish(p)?;
                let t = Instant::now();
                unpack(range, self, s, st);
                self.phases.unpack_s += t.elapsed().as_secs_f64();
            }
        }
        if let Some((p, range)) = in_flight {
            let (s, st) = (p.slot, p.stride);
            self.finish(p)?;
            let t = Instant::now();
            unpack(range, self, s, st);
            self.phases.unpack_s += t.elapsed().as_secs_f64();
        }
        self.phases.frames += n as u64;
        Ok(())
    }
}

/// Structure-of-arrays stride of a chunk of `n` frames: `n` rounded up to a workgroup.
fn stride(n: usize) -> usize {
    n.div_ceil(64) * 64
}

/// A chunk submitted and being read back.
struct Pending {
    slot: usize,
    rows: usize,
    /// Structure-of-arrays stride of this chunk.
    stride: usize,
    index: wgpu::SubmissionIndex,
    rx: std::sync::mpsc::Receiver<Result<(), wgpu::BufferAsyncError>>,
}

impl BatchBackend for WgpuBackend {
    fn name(&self) -> &'static str {
        "wgpu"
    }

    fn device(&self) -> String {
        format!("wgpu: {}, {}", self.adapter, self.precision.name())
    }

    fn linearize(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [FrameModel],
    ) -> Result<(), BackendError> {
        let np = self.np;
        check_shape(frames.len(), proxies.len(), out.len(), np)?;
        self.run(frames, proxies, true, |range, me, slot, cap| {
            let (r, ho, refs) = (me.rows, &me.host_out, &me.refs[slot]);
            out[range].par_iter_mut().enumerate().for_each(|(i, o)| {
                let gn = &mut o.gn;
                gn.energy = ho.get(i);
                gn.marker_sq_sum = ho.get(cap + i);
                gn.markers_used = ho.get(2 * cap + i) as usize;
                for k in 0..np {
                    gn.g[k] = ho.get((r.o_g + k) * cap + i);
                }
                let mut e = r.o_h;
                for k in 0..np {
                    for l in k..np {
                        let v = ho.get(e * cap + i);
                        gn.h[(k, l)] = v;
                        gn.h[(l, k)] = v;
                        e += 1;
                    }
                }
                let c = refs[i];
                for (j, x) in o.markers.iter_mut().enumerate() {
                    *x = ho.get((r.o_x + j) * cap + i) + c[j % 3];
                }
            });
        })
    }

    fn energy(
        &mut self,
        frames: &[FrameProblem<'_>],
        proxies: &[f64],
        out: &mut [EnergyEval],
    ) -> Result<(), BackendError> {
        check_shape(frames.len(), proxies.len(), out.len(), self.np)?;
        self.run(frames, proxies, false, |range, me, _, cap| {
            let ho = &me.host_out;
            for (i, o) in out[range].iter_mut().enumerate() {
                *o = EnergyEval {
                    energy: ho.get(i),
                    marker_sq_sum: ho.get(cap + i),
                    markers_used: ho.get(2 * cap + i) as usize,
                };
            }
        })
    }
}
