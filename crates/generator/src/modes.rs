//! B's predicted modes as the generator's choices, and their slowed copies.

use burn::tensor::{Device, Tensor};

/// B's predicted marginal modes, the generator's choices
/// ([`crate::GeneratorConfig::modes`]); see [`crate::b_modes`].
#[derive(Debug, Clone)]
pub struct BModes {
    /// `[batch, K, T, 2]` mode means in B's frame (metres).
    pub xy: Tensor<4>,
    /// `[batch, K]` log-probabilities of the modes.
    pub log_prob: Tensor<2>,
    /// `[batch, K]` each mode's courtesy ψ_k ([`crate::mode_courtesy`]); required by
    /// [`crate::Generator::forward`].
    pub psi: Option<Tensor<2>>,
    /// The leading modes that form the predicted mixture (their probabilities sum to 1);
    /// the rest are copies derived from them ([`BModes::with_slowdowns`]).
    pub mixture_modes: usize,
}

impl BModes {
    /// The rows repeated `times` times (row `r` of repetition `j` is row `j·batch + r`).
    pub fn repeat_rows(self, times: usize) -> Self {
        if times == 1 {
            return self;
        }
        Self {
            xy: Tensor::cat(vec![self.xy; times], 0),
            log_prob: Tensor::cat(vec![self.log_prob; times], 0),
            psi: self.psi.map(|p| Tensor::cat(vec![p; times], 0)),
            mixture_modes: self.mixture_modes,
        }
    }

    /// The modes followed by their slowed copies ([`crate::GeneratorConfig::mode_slowdowns`]),
    /// warp by warp, each with its mode's log-probability; unchanged without `warp`. Call it
    /// before the modes' courtesy is measured.
    ///
    /// # Shapes
    /// `warp: [S, T, T]`; `xy: [batch, K, T, 2]` → `[batch, K · (1 + S), T, 2]`
    ///
    /// # Panics
    /// If the modes' courtesy is already set (it would not cover the copies).
    pub fn with_slowdowns(self, warp: Option<&Tensor<3>>) -> Self {
        let Some(warp) = warp else {
            return self;
        };
        assert!(self.psi.is_none(), "slow the modes before scoring them");
        let [b, k, t, _] = self.xy.dims();
        let [s, _, _] = warp.dims();
        let flat = self.xy.clone().reshape([b * k, t, 2]);
        let mut xy = vec![self.xy];
        for i in 0..s {
            let w = warp.clone().narrow(0, i, 1).expand([b * k, t, t]);
            xy.push(w.matmul(flat.clone()).reshape([b, k, t, 2]));
        }
        Self {
            xy: Tensor::cat(xy, 1),
            log_prob: Tensor::cat(vec![self.log_prob; 1 + s], 1),
            psi: None,
            mixture_modes: self.mixture_modes,
        }
    }
}

/// The `[S, T, T]` time warps of [`crate::GeneratorConfig::mode_slowdowns`]: row `s` of warp `i`
/// holds the weights of a mode's steps (positions at steps 1‥T, the origin at step 0 is B's
/// current position, zero in B's frame) in its slowed copy's step `s + 1`. With factor `w`
/// the slowed copy is at the mode's fractional step `τ(t) = t − (1 − w) t² / (2T)` at step
/// `t`, linearly interpolated: its speed is the mode's times `1 − (1 − w) t / T`, smooth at
/// the current step (no jump in speed) and `w` times the mode's at the horizon.
///
/// A factor above 1 hurries the mode instead: past the horizon (`τ > T`) the copy extends the
/// mode's last step straight on. Factors are clamped to `[0, MAX_SPEEDUP]`
/// ([`MAX_SPEEDUP`]).
pub fn slowdown_warp(slowdowns: &[f32], steps: usize, device: &Device) -> Option<Tensor<3>> {
    if slowdowns.is_empty() || steps == 0 {
        return None;
    }
    Some(Tensor::from_data(
        burn::tensor::TensorData::new(
            slowdown_weights(slowdowns, steps),
            [slowdowns.len(), steps, steps],
        ),
        device,
    ))
}

/// The weights of [`slowdown_warp`], row-major `[S, T, T]`.
fn slowdown_weights(slowdowns: &[f32], steps: usize) -> Vec<f32> {
    let t_max = steps as f32;
    let mut weights = vec![0.0f32; slowdowns.len() * steps * steps];
    for (i, &w) in slowdowns.iter().enumerate() {
        let w = w.clamp(0.0, MAX_SPEEDUP);
        for s in 0..steps {
            let t = (s + 1) as f32;
            let tau = (t - (1.0 - w) * t * t / (2.0 * t_max)).max(0.0);
            let row = i * steps * steps + s * steps;
            if tau > t_max {
                // p(τ) = p_T + (τ − T)(p_T − p_{T−1}); p_0 is the origin (zero).
                let e = tau - t_max;
                weights[row + steps - 1] += 1.0 + e;
                if steps >= 2 {
                    weights[row + steps - 2] -= e;
                }
                continue;
            }
            let lo = tau.floor() as usize; // 0 = the origin
            let frac = tau - lo as f32;
            if lo >= 1 {
                weights[row + lo - 1] += 1.0 - frac;
            }
            if lo < steps && frac > 0.0 {
                weights[row + lo] += frac;
            }
        }
    }
    weights
}

/// One future slowed (or hurried) by factor `w` as [`slowdown_warp`] slows a mode: `future`
/// holds the positions at steps 1‥T in any frame, `origin` the position at step 0 in the same
/// frame.
pub fn slowed_future(future: &[[f64; 2]], origin: [f64; 2], w: f32) -> Vec<[f64; 2]> {
    if w == 1.0 {
        return future.to_vec(); // the warp is the identity: keep the points to the bit
    }
    let steps = future.len();
    let weights = slowdown_weights(&[w], steps);
    (0..steps)
        .map(|s| {
            let row = &weights[s * steps..(s + 1) * steps];
            let mut p = origin;
            for (&wj, q) in row.iter().zip(future) {
                let wj = f64::from(wj);
                p[0] += wj * (q[0] - origin[0]);
                p[1] += wj * (q[1] - origin[1]);
            }
            p
        })
        .collect()
}

/// The largest factor of [`slowdown_warp`] (larger ones are clamped to it): a copy that ends
/// at twice its mode's speed.
pub const MAX_SPEEDUP: f32 = 2.0;

/// Two modes of B in a row: a straight one along x and one turning to +y (`[2, 80, 2]`).
#[cfg(test)]
pub(crate) fn two_modes(device: &Device) -> Tensor<3> {
    let xy: Vec<f32> = (0..2)
        .flat_map(|k| {
            (1..=80).flat_map(move |s| [s as f32, if k == 1 { 0.1 * s as f32 } else { 0.0 }])
        })
        .collect();
    Tensor::from_data(burn::tensor::TensorData::new(xy, [2, 80, 2]), device)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slowed copy keeps its mode's path and eases off smoothly: on a straight mode at
    /// 1 m a step, factor ½ starts at the mode's speed, ends at half of it and covers
    /// `T (1 + w) / 2` = 60 m of the mode's 80; factor 1 is the mode itself.
    #[test]
    fn slowed_copies_ease_off_along_the_modes_path() {
        let device = Device::flex();
        let warp = slowdown_warp(&[1.0, 0.5], 80, &device).unwrap();
        assert_eq!(warp.dims(), [2, 80, 80]);
        let modes = BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[-0.1f32, -2.0]], &device),
            psi: None,
            mixture_modes: 2,
        };
        let out = modes.with_slowdowns(Some(&warp));
        assert_eq!(out.xy.dims(), [1, 6, 80, 2]);
        assert_eq!(out.mixture_modes, 2);
        let lp: Vec<f32> = out.log_prob.into_data().try_to_vec().unwrap();
        assert_eq!(lp, vec![-0.1, -2.0, -0.1, -2.0, -0.1, -2.0]);
        let xy: Vec<f32> = out.xy.into_data().try_to_vec().unwrap();
        let at = |c: usize, s: usize| [xy[(c * 80 + s) * 2], xy[(c * 80 + s) * 2 + 1]];
        for s in 0..80 {
            // Factor 1: the modes themselves.
            for k in 0..2 {
                let (a, b) = (at(k, s), at(2 + k, s));
                assert!((a[0] - b[0]).abs() < 1e-4 && (a[1] - b[1]).abs() < 1e-4);
            }
            // Factor ½ of the turning mode stays on its line y = 0.1 x.
            let p = at(5, s);
            assert!((p[1] - 0.1 * p[0]).abs() < 1e-4, "{p:?}");
        }
        let x = |s: usize| at(4, s)[0];
        assert!((x(79) - 60.0).abs() < 1e-3, "{}", x(79));
        assert!((x(0) - (1.0 - 0.5 / 160.0)).abs() < 1e-4, "{}", x(0));
        let speeds: Vec<f32> = (1..80).map(|s| x(s) - x(s - 1)).collect();
        assert!(speeds.windows(2).all(|w| w[1] <= w[0] + 1e-4), "eases off");
        assert!((speeds[78] - 0.5).abs() < 0.02, "{}", speeds[78]);
    }

    /// One future slowed on the host, in a frame whose origin is not B's position, is the
    /// tensor warp's copy of it in B's frame, moved back.
    #[test]
    fn a_slowed_future_in_any_frame_is_the_warped_mode() {
        let device = Device::flex();
        let modes = two_modes(&device);
        let warp = slowdown_warp(&[0.5], 80, &device).unwrap();
        let warped: Vec<f32> = warp
            .expand([2, 80, 80])
            .matmul(modes.clone())
            .into_data()
            .try_to_vec()
            .unwrap();
        let xy: Vec<f32> = modes.into_data().try_to_vec().unwrap();
        let origin = [120.0, -35.0];
        let turning: Vec<[f64; 2]> = (0..80)
            .map(|s| {
                let i = (80 + s) * 2;
                [
                    origin[0] + f64::from(xy[i]),
                    origin[1] + f64::from(xy[i + 1]),
                ]
            })
            .collect();
        let slowed = slowed_future(&turning, origin, 0.5);
        assert_eq!(slowed.len(), 80);
        for (s, p) in slowed.iter().enumerate() {
            let i = (80 + s) * 2;
            let want = [f64::from(warped[i]), f64::from(warped[i + 1])];
            assert!(
                (p[0] - origin[0] - want[0]).abs() < 1e-3,
                "{s}: {p:?} {want:?}"
            );
            assert!(
                (p[1] - origin[1] - want[1]).abs() < 1e-3,
                "{s}: {p:?} {want:?}"
            );
        }
        assert_eq!(slowed_future(&turning, origin, 1.0)[41], turning[41]);
    }

    /// A factor above 1 hurries the mode along its path: factor 1.5 on the turning mode
    /// (1 m a step along x) starts at the mode's speed, ends at 1.5 times it and reaches
    /// `T (1 + w) / 2` = 100 m along x, the last 20 m extending the mode's last step, still
    /// on its line.
    #[test]
    fn hurried_copies_speed_up_and_extend_the_mode() {
        let device = Device::flex();
        let warp = slowdown_warp(&[1.5], 80, &device).unwrap();
        let out = BModes {
            xy: two_modes(&device).reshape([1, 2, 80, 2]),
            log_prob: Tensor::from_data([[-0.1f32, -2.0]], &device),
            psi: None,
            mixture_modes: 2,
        }
        .with_slowdowns(Some(&warp));
        let xy: Vec<f32> = out.xy.into_data().try_to_vec().unwrap();
        let at = |s: usize| [xy[(3 * 80 + s) * 2], xy[(3 * 80 + s) * 2 + 1]];
        for s in 0..80 {
            let p = at(s);
            assert!((p[1] - 0.1 * p[0]).abs() < 1e-3, "{s}: {p:?}");
        }
        assert!((at(79)[0] - 100.0).abs() < 1e-3, "{:?}", at(79));
        assert!((at(0)[0] - (1.0 + 0.5 / 160.0)).abs() < 1e-4, "{:?}", at(0));
        let speeds: Vec<f32> = (1..80).map(|s| at(s)[0] - at(s - 1)[0]).collect();
        assert!(speeds.windows(2).all(|w| w[1] >= w[0] - 1e-3), "speeds up");
        assert!((speeds[78] - 1.5).abs() < 0.02, "{}", speeds[78]);
    }

    /// On a curving mode that slows down, a hurried copy is the mode's own point at the warped
    /// step `τ(t)` (interpolated between its steps) up to the horizon, and the last step's
    /// straight extension `p_T + (τ − T)(p_T − p_{T−1})` past it, computed here on the host.
    /// Factors above [`MAX_SPEEDUP`] are clamped to it; a one-step mode extends from the
    /// origin.
    #[test]
    fn hurried_copies_follow_a_curving_slowing_mode_and_clamp() {
        let device = Device::flex();
        let t_max = 80usize;
        // Speed 1 − s/160 m a step along x, on the parabola y = 0.01 x².
        let p = |s: usize| {
            let x = s as f32 - (s * s) as f32 / 320.0;
            [x, 0.01 * x * x]
        };
        let xy: Vec<f32> = (1..=t_max).flat_map(p).collect();
        let mode =
            Tensor::<4>::from_data(burn::tensor::TensorData::new(xy, [1, 1, t_max, 2]), &device);
        for (w, expect_w) in [(1.5f32, 1.5f32), (3.0, MAX_SPEEDUP)] {
            let warp = slowdown_warp(&[w], t_max, &device).unwrap();
            let out = BModes {
                xy: mode.clone(),
                log_prob: Tensor::from_data([[0.0f32]], &device),
                psi: None,
                mixture_modes: 1,
            }
            .with_slowdowns(Some(&warp));
            let got: Vec<f32> = out.xy.narrow(1, 1, 1).into_data().try_to_vec().unwrap();
            for t in 1..=t_max {
                let tf = t as f32;
                let tau = tf - (1.0 - expect_w) * tf * tf / (2.0 * t_max as f32);
                let want = if tau > t_max as f32 {
                    let (a, b) = (p(t_max), p(t_max - 1));
                    let e = tau - t_max as f32;
                    [a[0] + e * (a[0] - b[0]), a[1] + e * (a[1] - b[1])]
                } else {
                    let lo = tau.floor() as usize;
                    let f = tau - lo as f32;
                    let at = |s: usize| if s == 0 { [0.0, 0.0] } else { p(s) };
                    let (a, b) = (at(lo), at((lo + 1).min(t_max)));
                    [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])]
                };
                let g = [got[(t - 1) * 2], got[(t - 1) * 2 + 1]];
                assert!(
                    (g[0] - want[0]).abs() < 1e-3 && (g[1] - want[1]).abs() < 1e-3,
                    "w {w}, step {t}: {g:?} against {want:?}"
                );
            }
        }
        // One step: τ(1) = 1 + (1.5 − 1) / 2 = 1.25, the point 1.25 times the first.
        let warp: Vec<f32> = slowdown_warp(&[1.5], 1, &device)
            .unwrap()
            .into_data()
            .try_to_vec()
            .unwrap();
        assert_eq!(warp, vec![1.25]);
    }
}
