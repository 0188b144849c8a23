use super::*;

/// Ground truth moving from the origin heading +x at `speed`, ending at `end` with `end_heading`
/// (straight-line interpolation), all 80 steps valid.
fn gt_to(end: [f32; 2], end_heading: f32, speed: f32) -> GroundTruth {
    let n = FUTURE_STEPS;
    GroundTruth {
        current_xy_m: [0.0, 0.0],
        current_heading_rad: 0.0,
        current_velocity_mps: [speed, 0.0],
        future_xy_m: (1..=n)
            .map(|i| [end[0] * i as f32 / n as f32, end[1] * i as f32 / n as f32])
            .collect(),
        future_heading_rad: (1..=n).map(|i| end_heading * i as f32 / n as f32).collect(),
        future_velocity_mps: vec![[speed, 0.0]; n],
        future_valid: vec![true; n],
    }
}

#[test]
fn waymo_ap_test_vectors() {
    let a = [
        (0.3, true),
        (0.7, true),
        (0.4, false),
        (0.8, true),
        (0.5, false),
        (0.2, false),
    ];
    assert!((average_precision(&a, 4) - 0.65).abs() < 1e-6);
    let b = [
        (0.8, true),
        (0.5, false),
        (0.5, true),
        (0.5, true),
        (0.5, false),
        (0.5, false),
    ];
    assert!((average_precision(&b, 6) - 1.0 / 3.0).abs() < 1e-6);
    assert_eq!(average_precision(&[], 3), 0.0);
    assert!((average_precision(&[(0.9, true)], 1) - 1.0).abs() < 1e-6);
}

#[test]
fn every_bucket_pre_2024() {
    let t = ClassifierThresholds::PRE_2024;
    let c = |g: GroundTruth| classify_trajectory(&g, &t).unwrap();
    // Stationary: slow and less than 5 m.
    assert_eq!(c(gt_to([4.0, 0.0], 0.0, 1.0)), TrajectoryType::Stationary);
    // Fast but short is not stationary.
    assert_eq!(c(gt_to([4.0, 0.0], 0.0, 3.0)), TrajectoryType::Straight);
    assert_eq!(c(gt_to([80.0, 4.0], 0.1, 10.0)), TrajectoryType::Straight);
    assert_eq!(
        c(gt_to([80.0, 6.0], 0.1, 10.0)),
        TrajectoryType::StraightLeft
    );
    assert_eq!(
        c(gt_to([80.0, -6.0], -0.1, 10.0)),
        TrajectoryType::StraightRight
    );
    assert_eq!(
        c(gt_to([30.0, 30.0], PI / 2.0, 10.0)),
        TrajectoryType::LeftTurn
    );
    assert_eq!(
        c(gt_to([30.0, -30.0], -PI / 2.0, 10.0)),
        TrajectoryType::RightTurn
    );
    // Right U-turn merged into right turn.
    assert_eq!(
        c(gt_to([-10.0, -10.0], -2.8, 10.0)),
        TrajectoryType::RightTurn
    );
    // Left U-turn needs longitudinal displacement below −5 m in the pre-2024 set.
    assert_eq!(c(gt_to([-6.0, 10.0], PI, 10.0)), TrajectoryType::LeftUTurn);
    assert_eq!(c(gt_to([-3.0, 10.0], PI, 10.0)), TrajectoryType::LeftTurn);
}

#[test]
fn current_thresholds_differ_where_documented() {
    let t = ClassifierThresholds::CURRENT;
    let c = |g: GroundTruth| classify_trajectory(&g, &t).unwrap();
    assert_eq!(c(gt_to([4.0, 0.0], 0.0, 1.0)), TrajectoryType::Straight);
    assert_eq!(c(gt_to([2.0, 0.0], 0.0, 1.0)), TrajectoryType::Stationary);
    assert_eq!(
        c(gt_to([80.0, 3.0], 0.1, 10.0)),
        TrajectoryType::StraightLeft
    );
    assert_eq!(c(gt_to([-3.0, 10.0], PI, 10.0)), TrajectoryType::LeftUTurn);
}

#[test]
fn speed_scale_is_piecewise_linear() {
    assert_eq!(speed_scale(0.0), 0.5);
    assert_eq!(speed_scale(1.39), 0.5);
    assert!((speed_scale(6.2) - 0.75).abs() < 1e-6);
    assert_eq!(speed_scale(11.5), 1.0);
}

fn pred_of(trajs: Vec<Vec<[f32; 2]>>, scores: Vec<f32>) -> Prediction {
    Prediction {
        step_indices: Prediction::steps_10hz(),
        trajectories: trajs,
        scores,
    }
}

#[test]
fn miss_test_uses_the_ground_truth_heading_frame() {
    // Ground truth heading +y at the end (a left turn); a prediction 1.5 m off along +x is a
    // *lateral* error in that frame: over the 3 s lateral threshold × scale? At 8 s the
    // thresholds are (3.0 lat, 6.0 lon); speed 20 m/s → scale 1.
    let mut gt = gt_to([30.0, 30.0], PI / 2.0, 20.0);
    gt.future_heading_rad = vec![PI / 2.0; FUTURE_STEPS];
    let shift = |dx: f32, dy: f32| {
        gt.future_xy_m
            .iter()
            .map(|p| [p[0] + dx, p[1] + dy])
            .collect::<Vec<_>>()
    };
    // 4 m along world x = 4 m lateral in the GT frame (> 3.0): miss at 8 s.
    let table = evaluate(
        &[pred_of(vec![shift(4.0, 0.0)], vec![1.0])],
        std::slice::from_ref(&gt),
        &ClassifierThresholds::default(),
    );
    assert_eq!(table.by_time[2].1.miss_rate, Some(1.0));
    // 4 m along world y = 4 m longitudinal (< 6.0): hit.
    let table = evaluate(
        &[pred_of(vec![shift(0.0, 4.0)], vec![1.0])],
        std::slice::from_ref(&gt),
        &ClassifierThresholds::default(),
    );
    assert_eq!(table.by_time[2].1.miss_rate, Some(0.0));
    // Slow object: scale 0.5 halves the threshold: 2 m longitudinal still hits at 8 s (< 3), 3.5 m misses.
    let mut slow = gt.clone();
    slow.current_velocity_mps = [1.0, 0.0];
    let shift_slow = |dy: f32| {
        slow.future_xy_m
            .iter()
            .map(|p| [p[0], p[1] + dy])
            .collect::<Vec<_>>()
    };
    let t = evaluate(
        &[pred_of(vec![shift_slow(2.0)], vec![1.0])],
        std::slice::from_ref(&slow),
        &ClassifierThresholds::default(),
    );
    assert_eq!(t.by_time[2].1.miss_rate, Some(0.0));
    let t = evaluate(
        &[pred_of(vec![shift_slow(3.5)], vec![1.0])],
        std::slice::from_ref(&slow),
        &ClassifierThresholds::default(),
    );
    assert_eq!(t.by_time[2].1.miss_rate, Some(1.0));
}

#[test]
fn ade_min_ade_min_fde_and_map() {
    let gt = gt_to([80.0, 0.0], 0.0, 10.0);
    let off = |d: f32| {
        gt.future_xy_m
            .iter()
            .map(|p| [p[0], p[1] + d])
            .collect::<Vec<_>>()
    };
    // Two predictions: 2 m off with the higher score, 1 m off with the lower one.
    let pred = pred_of(vec![off(2.0), off(1.0)], vec![0.7, 0.3]);
    let t = evaluate(
        &[pred],
        std::slice::from_ref(&gt),
        &ClassifierThresholds::default(),
    );
    for (_, m) in &t.by_time {
        assert!((m.ade.unwrap() - 2.0).abs() < 1e-5);
        assert!((m.min_ade.unwrap() - 1.0).abs() < 1e-5);
        assert!((m.min_fde.unwrap() - 1.0).abs() < 1e-5);
    }
    // 3 s lateral threshold 1.0 × scale(10 m/s) = 0.953: both miss → MR 1, AP 0.
    let (_, m3) = &t.by_time[0];
    assert_eq!(m3.miss_rate, Some(1.0));
    assert_eq!(m3.map, Some(0.0));
    // 8 s threshold 3.0 × 0.953: both hit. mAP: sorted by score, the first is a TP → AP 1;
    // the second TP is an FP for mAP (still AP 1: precision at the only recall point is 1)
    // and dropped for soft mAP.
    let (_, m8) = &t.by_time[2];
    assert_eq!(m8.miss_rate, Some(0.0));
    assert_eq!(m8.map, Some(1.0));
    assert_eq!(m8.soft_map, Some(1.0));
    assert!((t.mean.min_ade.unwrap() - 1.0).abs() < 1e-5);
}

#[test]
fn map_penalises_a_confident_miss_and_soft_map_ignores_extra_hits() {
    // Object 1: best-scored prediction misses, second hits. Object 2: two hits.
    let gt = gt_to([80.0, 0.0], 0.0, 20.0);
    let off = |d: f32| {
        gt.future_xy_m
            .iter()
            .map(|p| [p[0], p[1] + d])
            .collect::<Vec<_>>()
    };
    let p1 = pred_of(vec![off(10.0), off(0.0)], vec![0.9, 0.1]);
    let p2 = pred_of(vec![off(0.0), off(0.5)], vec![0.6, 0.5]);
    let t = evaluate(
        &[p1, p2],
        &[gt.clone(), gt.clone()],
        &ClassifierThresholds::default(),
    );
    let (_, m8) = &t.by_time[2];
    // mAP samples: (0.9,F) (0.6,T) (0.5,F: second TP of object 2) (0.1,T); N = 2.
    // Sorted: 0.9F 0.6T 0.5F 0.1T → precisions 0, .5, .333, .5 → AP = ½·.5 + ½·.5 = 0.5.
    assert!((m8.map.unwrap() - 0.5).abs() < 1e-6);
    // Soft: (0.9,F) (0.6,T) (0.1,T) → precisions 0, .5, .667 → AP = ½·.667 + ½·.667 = 0.667.
    assert!((m8.soft_map.unwrap() - 2.0 / 3.0).abs() < 1e-5);
}

#[test]
fn two_hz_predictions_and_missing_ground_truth() {
    let mut gt = gt_to([80.0, 0.0], 0.0, 10.0);
    let steps = Prediction::steps_2hz();
    assert_eq!(steps[0], 4);
    assert_eq!(steps[15], 79);
    let pts: Vec<[f32; 2]> = steps
        .iter()
        .map(|&s| [gt.future_xy_m[s][0], gt.future_xy_m[s][1] + 1.0])
        .collect();
    let pred = Prediction {
        step_indices: steps,
        trajectories: vec![pts],
        scores: vec![1.0],
    };
    let t = evaluate(
        std::slice::from_ref(&pred),
        std::slice::from_ref(&gt),
        &ClassifierThresholds::default(),
    );
    assert!((t.mean.min_ade.unwrap() - 1.0).abs() < 1e-5);
    // With the 8 s step invalid, 8 s FDE / MR / mAP have no contributor (None) and the mean
    // is taken over 3 s and 5 s only.
    gt.future_valid[79] = false;
    let t = evaluate(&[pred], &[gt], &ClassifierThresholds::default());
    assert_eq!(t.by_time[2].1.min_fde, None);
    assert!(t.by_time[2].1.min_ade.is_some());
    assert!((t.mean.min_fde.unwrap() - 1.0).abs() < 1e-5);
}

/// A straight track whose heading crosses ±π (3.0 rad → −3.0 rad, a real change of 0.28 rad):
/// the pre-2024 classifier compares the raw difference (−6.0 rad) and calls it a left turn,
/// the current one wraps it and calls it straight-left (lateral offset 4.2 m > 2.5 m).
#[test]
fn heading_wrap_is_normalised_only_by_the_current_classifier() {
    let steps = 80;
    let heading0 = 3.0f32;
    let gt = GroundTruth {
        current_xy_m: [0.0, 0.0],
        current_heading_rad: heading0,
        current_velocity_mps: [-10.0, 0.0],
        future_xy_m: (1..=steps)
            .map(|i| [-30.0 * i as f32 / steps as f32, 0.0])
            .collect(),
        future_heading_rad: (1..=steps)
            .map(|i| if i < steps / 2 { 3.1 } else { -3.0 })
            .collect(),
        future_velocity_mps: vec![[-10.0, 0.0]; steps],
        future_valid: vec![true; steps],
    };
    assert_eq!(
        classify_trajectory(&gt, &ClassifierThresholds::PRE_2024),
        Some(TrajectoryType::LeftTurn)
    );
    assert_eq!(
        classify_trajectory(&gt, &ClassifierThresholds::CURRENT),
        Some(TrajectoryType::StraightLeft)
    );
    assert_eq!(
        ClassifierThresholds::default(),
        ClassifierThresholds::PRE_2024
    );
}
