//! Adapter and device acquisition, error capture and buffer readback.

use std::sync::{mpsc, Arc, Mutex};

use wgpu::util::DeviceExt;

use super::probe::dispatch_size;
use super::timing::PassTimer;

/// What went wrong on the GPU path.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter (Vulkan, Metal, DX12 or GL driver) could be found.
    #[error("no GPU adapter found ({0}); on Debian install `mesa-vulkan-drivers` for the lavapipe software rasterizer")]
    NoAdapter(String),
    /// The adapter refused to create a device.
    #[error("GPU device request failed: {0}")]
    Device(String),
    /// The scene does not fit the device's limits.
    #[error("scene too big for this GPU: {0}")]
    SceneTooBig(String),
    /// The device stopped working: a driver reset (a kernel that ran too long, another
    /// process, a removed GPU) or `destroy`.
    #[error("the GPU device was lost ({0}); nothing it computed is used")]
    DeviceLost(String),
    /// A shader failed to compose or compile.
    #[error("shader `{name}`: {problem}")]
    Shader {
        /// The kernel.
        name: String,
        /// What failed.
        problem: String,
    },
    /// The GPU path does not do this yet (the CPU does).
    #[error("not on the GPU yet: {0}")]
    Unsupported(String),
    /// wgpu reported a validation or out-of-memory error.
    #[error("GPU error during {what}: {problem}")]
    Operation {
        /// The operation.
        what: String,
        /// wgpu's message.
        problem: String,
    },
}

/// A wgpu device and queue with the adapter's own limits.
pub struct GpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, driver and backend of the adapter.
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with (the adapter's maximum).
    pub limits: wgpu::Limits,
    /// Arrays (by the names of their `#chunked` declarations,
    /// [`super::compose::ChunkedArray`]) split in chunks whatever their size, not only above
    /// the binding limit: the split path on small scenes, for tests. Empty by default.
    pub split_arrays: Vec<String>,
    /// Why the device was lost, once it is (set by wgpu's device-lost callback).
    lost: Arc<Mutex<Option<String>>>,
}

impl GpuContext {
    /// Opens the best available adapter with its full limits.
    pub fn new() -> Result<GpuContext, GpuError> {
        pollster::block_on(async {
            let instance = wgpu::Instance::new(
                wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
            );
            let adapter = instance
                .request_adapter(&wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::HighPerformance,
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
            let limits = adapter.limits();
            let (device, queue) = adapter
                .request_device(&wgpu::DeviceDescriptor {
                    label: Some("hytrace"),
                    required_limits: limits.clone(),
                    // Where the adapter has them: GPU-side timings of kernels, and the
                    // texture formats of the volume atlas' 3D textures (`super::texels`).
                    required_features: adapter.features()
                        & (wgpu::Features::TIMESTAMP_QUERY
                            | wgpu::Features::TEXTURE_COMPRESSION_BC
                            | wgpu::Features::TEXTURE_COMPRESSION_BC_SLICED_3D
                            | wgpu::Features::TEXTURE_FORMAT_16BIT_NORM),
                    ..Default::default()
                })
                .await
                .map_err(|e| GpuError::Device(e.to_string()))?;
            let lost = Arc::new(Mutex::new(None));
            let record = Arc::clone(&lost);
            device.set_device_lost_callback(move |reason, message| {
                if let Ok(mut lost) = record.lock() {
                    *lost = Some(format!("{reason:?}: {message}"));
                }
            });
            Ok(GpuContext {
                device,
                queue,
                adapter_info: adapter.get_info(),
                limits,
                split_arrays: Vec::new(),
                lost,
            })
        })
    }

    /// For tests: a context, or `None` with the reason printed. When `HYTRACE_REQUIRE_GPU=1`
    /// a missing adapter panics instead, so CI cannot pass by skipping GPU tests.
    pub fn for_tests() -> Option<GpuContext> {
        match GpuContext::new() {
            Ok(ctx) => {
                eprintln!("GPU tests on: {}", ctx.describe());
                Some(ctx)
            }
            Err(e) if std::env::var("HYTRACE_REQUIRE_GPU").as_deref() == Ok("1") => {
                panic!("HYTRACE_REQUIRE_GPU=1 but no GPU is usable: {e}")
            }
            Err(e) => {
                eprintln!("SKIPPED: GPU test needs an adapter: {e}");
                None
            }
        }
    }

    /// One line describing the adapter.
    pub fn describe(&self) -> String {
        let i = &self.adapter_info;
        format!(
            "{} ({:?}, {:?}, driver {} {})",
            i.name, i.device_type, i.backend, i.driver, i.driver_info
        )
    }

    /// [`GpuError::DeviceLost`] once the device is lost, with wgpu's reason.
    pub fn check_not_lost(&self) -> Result<(), GpuError> {
        let lost = self.lost.lock().map(|l| l.clone()).unwrap_or(None);
        lost.map_or(Ok(()), |reason| Err(GpuError::DeviceLost(reason)))
    }

    /// Runs `f`, turning any validation or out-of-memory error it causes into a [`GpuError`]
    /// (a lost device first, as such).
    pub fn checked<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, GpuError> {
        self.check_not_lost()?;
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        let errors = pollster::block_on(async { (validation.pop().await, oom.pop().await) });
        self.check_not_lost()?;
        match errors {
            (Some(e), _) | (None, Some(e)) => Err(GpuError::Operation {
                what: what.to_string(),
                problem: e.to_string(),
            }),
            (None, None) => Ok(value),
        }
    }

    /// A shader module compiled from WGSL `source`.
    pub fn wgsl_module(&self, label: &str, source: &str) -> wgpu::ShaderModule {
        self.device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    }

    /// A bind group layout of storage buffers at bindings `0..count`, read-only but for
    /// the bindings in `writable`.
    pub fn storage_layout(
        &self,
        label: &str,
        count: u32,
        writable: &[u32],
    ) -> wgpu::BindGroupLayout {
        self.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &(0..count)
                    .map(|b| storage_layout_entry(b, !writable.contains(&b)))
                    .collect::<Vec<_>>(),
            })
    }

    /// The pipeline layout of a kernel with the bind group layouts `groups` (group 0 first;
    /// `None` for a group it does not use).
    pub fn pipeline_layout(
        &self,
        label: &str,
        groups: &[Option<&wgpu::BindGroupLayout>],
    ) -> wgpu::PipelineLayout {
        self.device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some(label),
                bind_group_layouts: groups,
                immediate_size: 0,
            })
    }

    /// A bind group layout of read-only storage buffers at `bindings`.
    pub fn read_only_layout(&self, label: &str, bindings: &[u32]) -> wgpu::BindGroupLayout {
        self.device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some(label),
                entries: &self.read_only_entries(bindings),
            })
    }

    /// The entries of [`GpuContext::read_only_layout`], for a layout with more entries.
    pub fn read_only_entries(&self, bindings: &[u32]) -> Vec<wgpu::BindGroupLayoutEntry> {
        (bindings.iter())
            .map(|&b| storage_layout_entry(b, true))
            .collect()
    }

    /// Named arrays uploaded as read-only storage buffers, in order;
    /// [`GpuError::SceneTooBig`] names the first array above the device's binding limit.
    pub fn storage_buffers(
        &self,
        arrays: &[(&str, Vec<u8>)],
    ) -> Result<Vec<wgpu::Buffer>, GpuError> {
        let limit = self.limits.max_storage_buffer_binding_size;
        if let Some((name, bytes)) = arrays.iter().find(|(_, b)| b.len() as u64 > limit) {
            return Err(GpuError::SceneTooBig(format!(
                "array `{name}` has {} bytes, the device binds at most {limit}",
                bytes.len()
            )));
        }
        self.checked("uploading arrays", || {
            arrays
                .iter()
                .map(|(name, bytes)| self.input_buffer(name, bytes))
                .collect()
        })
    }

    /// A read-only storage buffer holding `bytes`.
    pub fn input_buffer(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
            })
    }

    /// A uniform buffer holding `bytes`.
    pub fn uniform_buffer(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytes,
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// A storage buffer of `size` bytes for a kernel to write and the CPU to read back.
    pub fn output_buffer(&self, label: &str, size: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    }

    /// Records one compute pass over `items` invocations (64 per workgroup) that runs
    /// `pipelines` in order with the bind `groups` (index, group), timed by `timer` when
    /// given, and submits it.
    pub fn submit_pass(
        &self,
        label: &str,
        pipelines: &[&wgpu::ComputePipeline],
        groups: &[(u32, &wgpu::BindGroup)],
        items: u32,
        timer: Option<&PassTimer>,
    ) {
        self.submit_with(label, items, timer, |pass, (x, y)| {
            for (index, group) in groups {
                pass.set_bind_group(*index, *group, &[]);
            }
            for pipeline in pipelines {
                pass.set_pipeline(pipeline);
                pass.dispatch_workgroups(x, y, 1);
            }
        });
    }

    /// Records and submits one compute pass that dispatches `pipeline` over `items`
    /// invocations once per bind group of `varying` (set at index `varying.0` before each
    /// dispatch), with the `groups` shared by all, timed by `timer` when given.
    pub fn submit_sequence(
        &self,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        groups: &[(u32, &wgpu::BindGroup)],
        varying: (u32, &[wgpu::BindGroup]),
        items: u32,
        timer: Option<&PassTimer>,
    ) {
        self.submit_with(label, items, timer, |pass, (x, y)| {
            pass.set_pipeline(pipeline);
            for (index, group) in groups {
                pass.set_bind_group(*index, *group, &[]);
            }
            for group in varying.1 {
                pass.set_bind_group(varying.0, group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
        });
    }

    /// One timed compute pass whose dispatches `record` writes (given the workgroup grid
    /// for `items` invocations), submitted. Dispatches in one pass run in order.
    fn submit_with(
        &self,
        label: &str,
        items: u32,
        timer: Option<&PassTimer>,
        record: impl FnOnce(&mut wgpu::ComputePass<'_>, (u32, u32)),
    ) {
        let grid = dispatch_size(items, self.limits.max_compute_workgroups_per_dimension);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: timer.map(PassTimer::writes),
            });
            record(&mut pass, grid);
        }
        if let Some(timer) = timer {
            timer.resolve(&mut encoder);
        }
        self.queue.submit([encoder.finish()]);
    }

    /// Copies `size` bytes of a storage buffer back to the CPU.
    pub fn read_buffer(&self, buffer: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, GpuError> {
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([encoder.finish()]);
        let (tx, rx) = mpsc::channel();
        staging.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        // A lost device fails every step; its reason is the better message.
        let failed = |problem: String| match self.check_not_lost() {
            Err(lost) => lost,
            Ok(()) => GpuError::Operation {
                what: "readback".to_string(),
                problem,
            },
        };
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| failed(e.to_string()))?;
        rx.recv()
            .map_err(|e| failed(e.to_string()))?
            .map_err(|e| failed(e.to_string()))?;
        let bytes = staging
            .get_mapped_range(..)
            .map_err(|e| failed(e.to_string()))?
            .to_vec();
        self.check_not_lost()?;
        Ok(bytes)
    }
}

/// What `--backend auto` runs: `gpu` on a new context, or, when that fails on the GPU's
/// side (no adapter, a lost device, a scene too big for it, out of memory), a line on
/// stderr naming the failure and `cpu`. Failures that are not the GPU's (bad input) are
/// returned as they are.
pub fn gpu_or_cpu<R>(
    doing: &str,
    gpu: impl FnOnce(GpuContext) -> crate::Result<R>,
    cpu: impl FnOnce() -> crate::Result<R>,
) -> crate::Result<R> {
    match GpuContext::new().map_err(crate::Error::from).and_then(gpu) {
        Err(e) if matches!(e.without_context(), crate::Error::Gpu(_)) => {
            eprintln!("hytrace: not on the GPU ({e:#}); --backend auto {doing} on the CPU");
            cpu()
        }
        result => result,
    }
}

/// Layout entry of a storage buffer visible to compute shaders.
pub(super) fn storage_layout_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Layout entry of a uniform buffer visible to compute shaders.
pub(super) fn uniform_layout_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Bind group entries binding each of `buffers` whole, at bindings 0, 1, 2, ...
pub fn whole_buffer_entries(buffers: &[wgpu::Buffer]) -> Vec<wgpu::BindGroupEntry<'_>> {
    buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect()
}

/// A compute pipeline of entry point `entry` of `module` with `layout`, its `override`
/// constants set to `constants` (name, value).
pub fn compute_pipeline(
    ctx: &GpuContext,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    entry: &str,
    constants: &[(String, f64)],
) -> wgpu::ComputePipeline {
    let constants: Vec<(&str, f64)> = constants.iter().map(|(n, v)| (n.as_str(), *v)).collect();
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(entry),
            layout: Some(layout),
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                ..Default::default()
            },
            cache: None,
        })
}
