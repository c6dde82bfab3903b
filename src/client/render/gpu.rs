//! The GPU: an adapter and device, headless or able to present to a
//! window's surface, with timestamp queries when the adapter has them. `WGPU_BACKEND` (e.g.
//! `vulkan`, `gl`) picks the backend; on a machine without a GPU Mesa's
//! lavapipe serves Vulkan in software. Large allocations go through
//! [`allocate`]: a GPU out of memory is an error, where wgpu's default
//! handler for uncaptured errors panics.

/// Why no GPU could be opened.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter at all.
    #[error(
        "no GPU adapter found ({0}); without a GPU install Mesa's software Vulkan: apt-get install -y mesa-vulkan-drivers libvulkan1"
    )]
    NoAdapter(String),
    /// The adapter refused the device.
    #[error("the GPU refused a device: {0}")]
    Device(String),
    /// The adapter lacks what the renderer needs.
    #[error(
        "the GPU {0} lacks {1:?}: the renderer lights splats in compute shaders and counts rays from fragment shaders"
    )]
    Lacks(String, wgpu::DownlevelFlags),
}

/// GPU memory that could not be had.
#[derive(Debug, thiserror::Error)]
#[error("cannot allocate {what}: {why}")]
pub struct AllocError {
    /// What was wanted, e.g. "render targets of 640×480".
    pub what: String,
    /// Why not: out of GPU memory, or beyond one of the GPU's limits.
    pub why: String,
}

/// The GPU objects `make` creates, or an [`AllocError`] for `what` if the
/// device ran out of memory making them.
pub fn allocate<T>(device: &wgpu::Device, what: String, make: impl FnOnce() -> T) -> Result<T, AllocError> {
    let scope = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let made = make();
    match pollster::block_on(scope.pop()) {
        None => Ok(made),
        Some(_) => Err(AllocError { what, why: "out of GPU memory".into() }),
    }
}

/// What the renderer needs beyond WebGPU's downlevel defaults.
const NEEDED: wgpu::DownlevelFlags =
    wgpu::DownlevelFlags::COMPUTE_SHADERS.union(wgpu::DownlevelFlags::FRAGMENT_WRITABLE_STORAGE);

/// An opened GPU.
pub struct Gpu {
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// What it is, for reports.
    pub info: wgpu::AdapterInfo,
    /// Whether render passes can write timestamps.
    pub timestamps: bool,
    /// Whether fragment shaders may promise how they change depth
    /// (`@early_depth_test`), so hidden fragments can be rejected before
    /// they run.
    pub early_depth: bool,
}

impl Gpu {
    /// Opens the best adapter, headless.
    pub fn open() -> Result<Gpu, GpuError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        Gpu::open_on(&instance, None)
    }

    /// Opens the best adapter of `instance`, one that can present to
    /// `surface` if given.
    pub fn open_on(instance: &wgpu::Instance, surface: Option<&wgpu::Surface>) -> Result<Gpu, GpuError> {
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            compatible_surface: surface,
            ..Default::default()
        };
        let adapter =
            pollster::block_on(instance.request_adapter(&options)).map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let missing = NEEDED.difference(adapter.get_downlevel_capabilities().flags);
        if !missing.is_empty() {
            return Err(GpuError::Lacks(adapter.get_info().name, missing));
        }
        let wanted = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::SHADER_EARLY_DEPTH_TEST;
        let required_features = adapter.features() & wanted;
        let timestamps = required_features.contains(wgpu::Features::TIMESTAMP_QUERY);
        // Not on GL: the promise clamps a ray's depth to the rasterised
        // one, which GL's −1..1 depth range leaves too coarse far away.
        let early_depth = required_features.contains(wgpu::Features::SHADER_EARLY_DEPTH_TEST)
            && adapter.get_info().backend != wgpu::Backend::Gl;
        let desc = wgpu::DeviceDescriptor {
            label: Some("sylva"),
            required_features,
            required_limits: adapter.limits(),
            ..Default::default()
        };
        let (device, queue) =
            pollster::block_on(adapter.request_device(&desc)).map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(Gpu { info: adapter.get_info(), adapter, device, queue, timestamps, early_depth })
    }

    /// A one-line description: name, backend, driver.
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {} {})", self.info.name, self.info.backend, self.info.driver, self.info.driver_info)
    }
}
