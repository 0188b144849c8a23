//! Backend selection: the only place that names a backend.

use burn::tensor::Device;

/// Error for an unknown or not-compiled-in backend name: `.0` is the requested name, `.1` the
/// comma-separated list of [`available_backends`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("backend {0:?} is not available in this build (available: {1})")]
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
        "vulkan" => Ok(Device::vulkan(Default::default())),
        other => Err(UnknownBackend(
            other.to_string(),
            available_backends().join(", "),
        )),
    }
}

/// A CPU device on which to build a model only to count its parameters.
pub fn parameter_count_device() -> Device {
    Device::flex()
}

/// The training device (with autodiff) for a backend name.
pub fn training_device(name: &str) -> Result<Device, UnknownBackend> {
    Ok(device(name)?.autodiff())
}
