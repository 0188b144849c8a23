//! Backend selection: the only place that names a backend.

use burn::tensor::Device;

/// Error for a backend that cannot be used: an unknown or not-compiled-in name, or a GPU
/// backend whose device does not answer. `.0` is the requested name, `.1` why (for a name, the
/// comma-separated list of [`available_backends`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("backend {0:?} is not available: {1}")]
pub struct UnknownBackend(pub String, pub String);

/// Backends compiled into this build.
pub fn available_backends() -> Vec<&'static str> {
    let mut v = vec!["flex"];
    if cfg!(feature = "tch") {
        v.push("tch");
    }
    if cfg!(feature = "cuda") {
        v.push("cuda");
    }
    if cfg!(feature = "vulkan") {
        v.push("vulkan");
    }
    v
}

/// The inference device for a backend name: `flex` (pure Rust CPU, default), `tch`
/// (LibTorch CPU, `--features tch`), `cuda` (`--features cuda`, needs network to build),
/// `vulkan` (`--features vulkan`: the default GPU adapter through wgpu's Vulkan path).
pub fn device(name: &str) -> Result<Device, UnknownBackend> {
    match name {
        "flex" => Ok(Device::flex()),
        #[cfg(feature = "tch")]
        "tch" => Ok(Device::libtorch()),
        #[cfg(feature = "cuda")]
        "cuda" => Ok(Device::cuda(burn::tensor::DeviceIndex::Default)),
        #[cfg(feature = "vulkan")]
        "vulkan" => {
            let device = Device::vulkan(Default::default());
            if answers(&device) {
                Ok(device)
            } else {
                Err(UnknownBackend(
                    "vulkan".into(),
                    "no Vulkan adapter answered (it needs a GPU with a Vulkan driver and loader)"
                        .into(),
                ))
            }
        }
        other => Err(UnknownBackend(
            other.to_string(),
            format!("this build has {}", available_backends().join(", ")),
        )),
    }
}

/// Whether a GPU device runs a kernel: without an adapter wgpu panics in its own thread, which
/// this turns into `false` (asked once per process).
#[cfg(feature = "vulkan")]
fn answers(device: &Device) -> bool {
    static ANSWERS: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ANSWERS.get_or_init(|| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let t = burn::tensor::Tensor::<1>::from_floats([1.0, 2.0], device);
            let sum: f32 = t.sum().into_scalar();
            sum == 3.0
        }))
        .unwrap_or(false)
    })
}

/// A CPU device on which to build a model only to count its parameters.
pub fn parameter_count_device() -> Device {
    Device::flex()
}

/// The training device (with autodiff) for a backend name.
pub fn training_device(name: &str) -> Result<Device, UnknownBackend> {
    Ok(device(name)?.autodiff())
}
