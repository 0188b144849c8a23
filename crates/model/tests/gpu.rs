//! A forward and a backward pass on each GPU backend compiled into this build, checked against
//! the `flex` CPU backend. Without the backend's cargo feature, or without a GPU (adapter) that
//! answers, the test is reported as *ignored* — never as passed.
//!
//! `cargo test --release -p scbg-model --features vulkan --test gpu`

use libtest_mimic::{Arguments, Failed, Trial};
use scbg_model::fixtures::{PassCheck, forward_backward};

fn compare(name: &str, got: &PassCheck, reference: &PassCheck) -> Result<(), Failed> {
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-3 * (1.0 + b.abs());
    if got.xy_dims != reference.xy_dims {
        return Err(format!(
            "{name}: output dims {:?}, flex {:?}",
            got.xy_dims, reference.xy_dims
        )
        .into());
    }
    if !(close(got.loss, reference.loss) && close(got.loss_after_step, reference.loss_after_step)) {
        return Err(format!(
            "{name}: loss {} → {} after one step, flex {} → {}",
            got.loss, got.loss_after_step, reference.loss, reference.loss_after_step
        )
        .into());
    }
    if got.loss_after_step.partial_cmp(&got.loss) != Some(std::cmp::Ordering::Less) {
        return Err(format!("{name}: one Adam step did not lower the loss").into());
    }
    Ok(())
}

/// Whether a device of this backend can run a kernel (no adapter → a panic inside wgpu).
#[allow(dead_code)]
fn answers(device: &burn::tensor::Device) -> bool {
    std::panic::catch_unwind(|| {
        let t = burn::tensor::Tensor::<1>::from_floats([1.0, 2.0], device);
        let s: f32 = t.sum().into_scalar();
        s == 3.0
    })
    .unwrap_or(false)
}

fn backend_trial(name: &'static str) -> Trial {
    let compiled = scbg_model::device::available_backends().contains(&name);
    let device = compiled
        .then(|| scbg_model::device::device(name).ok())
        .flatten();
    let present = device.as_ref().is_some_and(answers);
    let label = match (compiled, present) {
        (false, _) => format!("{name}_forward_backward (not built: --features {name})"),
        (true, false) => format!("{name}_forward_backward (no GPU answers)"),
        (true, true) => format!("{name}_forward_backward"),
    };
    Trial::test(label, move || {
        let device = scbg_model::device::training_device(name).map_err(|e| e.to_string())?;
        let reference = forward_backward(&burn::tensor::Device::flex().autodiff());
        let got = forward_backward(&device);
        eprintln!(
            "{name}: loss {} → {}, flex {} → {}",
            got.loss, got.loss_after_step, reference.loss, reference.loss_after_step
        );
        compare(name, &got, &reference)
    })
    .with_ignored_flag(!present)
}

fn main() {
    let args = Arguments::from_args();
    // The reference itself, always run: it keeps the check honest on machines without a GPU.
    let reference = Trial::test("flex_forward_backward_learns", || {
        let r = forward_backward(&burn::tensor::Device::flex().autodiff());
        if r.loss.is_finite() && r.loss_after_step < r.loss {
            Ok(())
        } else {
            Err(format!("flex: loss {} → {}", r.loss, r.loss_after_step).into())
        }
    });
    let trials = vec![reference, backend_trial("vulkan"), backend_trial("cuda")];
    libtest_mimic::run(&args, trials).exit();
}
