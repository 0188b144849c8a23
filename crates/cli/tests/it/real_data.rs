//! Every fact of `shared/data/README.md`, asserted through `scbg data inspect --json`.

use crate::{inspect_json, real_dir};
use serde_json::json;

#[test]
fn genuine_scenario_files() {
    let Some(dir) = real_dir() else { return };
    let v = &inspect_json(&[&dir.join("womd/motion_data_one_scenario.tfrecord")])[0];
    assert_eq!(v["scenario_id"], "637f20cafde22ff8");
    assert_eq!(v["format"], "scenario");
    assert_eq!(v["num_steps"], 91);
    assert_eq!(v["current_time_index"], 10);
    assert_eq!(v["num_tracks"], 83);
    assert_eq!(v["tracks_by_type"]["vehicle"], 70);
    assert_eq!(v["tracks_by_type"]["pedestrian"], 10);
    assert_eq!(v["tracks_by_type"]["cyclist"], 3);
    assert_eq!(v["sdc_track_index"], 82);
    assert_eq!(v["num_map_features"], 301);
    assert_eq!(v["map_features_by_type"]["lane"], 199);
    assert_eq!(v["signal_steps"], 91);
    assert_eq!(v["tracks_to_predict"].as_array().unwrap().len(), 3);
    assert_eq!(v["objects_of_interest"], json!([]));

    let v = &inspect_json(&[&dir.join("womd/womd_scenario_input.tfrecord")])[0];
    assert_eq!(v["scenario_id"], "ee519cf571686d19");
    assert_eq!(v["num_steps"], 91);
    assert_eq!(v["num_tracks"], 257);
    assert_eq!(v["tracks_by_type"]["vehicle"], 189);
    assert_eq!(v["tracks_by_type"]["pedestrian"], 68);
    assert_eq!(v["num_map_features"], 215);
    assert_eq!(v["objects_of_interest"], json!([625, 2694]));
    assert_eq!(
        v["objects_of_interest_types"],
        json!(["vehicle", "pedestrian"])
    );
}

#[test]
fn genuine_tf_example_file() {
    let Some(dir) = real_dir() else { return };
    let v = &inspect_json(&[&dir.join("womd/motion_data_one_example.tfrecord")])[0];
    assert_eq!(v["format"], "tf_example");
    assert_eq!(v["scenario_id"], "a3bb37c25ce56418");
    assert_eq!(v["num_steps"], 91);
    assert_eq!(v["current_time_index"], 10);
    assert_eq!(v["objects_of_interest"], json!([7, 333]));
    assert_eq!(
        v["objects_of_interest_types"],
        json!(["vehicle", "cyclist"])
    );
    assert_eq!(v["tracks_to_predict"].as_array().unwrap().len(), 8);
    assert!(v["num_map_features"].as_u64().unwrap() > 0);
    // (72 keys, 128 slots and 20000 road-graph samples are asserted in scbg-womd's unit tests.)
}

#[test]
fn reencoded_womd_files() {
    let Some(dir) = real_dir() else { return };
    // scenario_id, steps, vehicles, pedestrians, cyclists, map features, objects_of_interest (+types)
    type Row<'a> = (&'a str, u64, u64, u64, u64, u64, &'a [(i64, &'a str)]);
    let table: [Row<'_>; 12] = [
        (
            "1c365f15b70ebdbf",
            91,
            23,
            2,
            0,
            118,
            &[(1847, "vehicle"), (1415, "vehicle")],
        ),
        (
            "2a1e44d405a6833f",
            91,
            184,
            25,
            2,
            358,
            &[(490, "vehicle"), (333, "vehicle")],
        ),
        (
            "2a173b334be3d32c",
            91,
            12,
            3,
            0,
            213,
            &[(2256, "vehicle"), (2540, "pedestrian")],
        ),
        (
            "db4edc9bd0c9d18c",
            91,
            68,
            12,
            1,
            102,
            &[(18, "vehicle"), (284, "cyclist")],
        ),
        ("2af8a17d6cee3f8", 91, 98, 2, 0, 174, &[]),
        ("68d5053e5693f4ca", 91, 90, 0, 1, 225, &[]),
        ("c403d5992cab9e0", 91, 134, 3, 1, 378, &[]),
        ("250011f460de6135", 198, 32, 1, 0, 115, &[]),
        ("4d320edc9cb801a3", 199, 172, 1, 1, 170, &[]),
        ("61fa872f2d274223", 199, 95, 33, 0, 70, &[]),
        ("6f85f27e0243fc10", 197, 69, 5, 1, 446, &[]),
        ("8799c31b5be1f312", 198, 26, 4, 6, 124, &[]),
    ];
    for (id, steps, veh, ped, cyc, map, ooi) in table {
        let v = &inspect_json(&[&dir.join(format!("womd-reencoded/{id}.tfrecord"))])[0];
        assert_eq!(v["scenario_id"], id);
        assert_eq!(v["num_steps"], steps, "{id}");
        assert_eq!(v["tracks_by_type"]["vehicle"], veh, "{id}");
        assert_eq!(v["tracks_by_type"]["pedestrian"], ped, "{id}");
        assert_eq!(v["tracks_by_type"]["cyclist"], cyc, "{id}");
        assert_eq!(v["num_map_features"], map, "{id}");
        let ids: Vec<i64> = ooi.iter().map(|x| x.0).collect();
        let types: Vec<&str> = ooi.iter().map(|x| x.1).collect();
        assert_eq!(v["objects_of_interest"], json!(ids), "{id}");
        assert_eq!(v["objects_of_interest_types"], json!(types), "{id}");
    }
}

#[test]
fn reencoded_nuscenes_files() {
    let Some(dir) = real_dir() else { return };
    for scene in [
        "0061", "0103", "0553", "0655", "0757", "0796", "0916", "1077", "1094", "1100",
    ] {
        let path = dir.join(format!("nuscenes-reencoded/scene-{scene}.tfrecord"));
        let v = &inspect_json(&[&path])[0];
        let steps = v["num_steps"].as_u64().unwrap();
        assert!((191..=201).contains(&steps), "scene-{scene}: {steps} steps");
        let tracks = v["num_tracks"].as_u64().unwrap();
        assert!(
            (30..=226).contains(&tracks),
            "scene-{scene}: {tracks} tracks"
        );
        assert_eq!(
            v["map_features_by_type"]["road_edge"], 0,
            "scene-{scene}: nuScenes has no road edges"
        );
    }
    // Cones and barriers are OBJECT type 4 (other).
    let v = &inspect_json(&[&dir.join("nuscenes-reencoded/scene-0061.tfrecord")])[0];
    assert!(v["tracks_by_type"]["other"].as_u64().unwrap() > 0);
}

fn read_scene(path: &std::path::Path) -> scbg_scene::Scene {
    let file = scbg_womd::WomdFile::open(path).unwrap();
    file.scenes().next().unwrap().unwrap()
}

#[test]
fn nuscenes_ids_and_flat_maps() {
    let Some(dir) = real_dir() else { return };
    for entry in std::fs::read_dir(dir.join("nuscenes-reencoded")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "tfrecord") {
            continue;
        }
        let scene = read_scene(&path);
        assert!(
            scene.tracks.iter().all(|t| t.id >= 1_000_000),
            "{}",
            path.display()
        );
        let m = &scene.map;
        let ids = m
            .lanes
            .iter()
            .map(|f| f.id)
            .chain(m.road_lines.iter().map(|f| f.id))
            .chain(m.crosswalks.iter().map(|f| f.id));
        assert!(
            ids.into_iter().all(|id| id >= 1_000_000),
            "{}",
            path.display()
        );
        // shared/data/README.md says "map z = 0": true of road lines; lane centrelines do carry
        // small non-zero z in these files (checked against the raw bytes independently).
        assert!(
            m.road_lines
                .iter()
                .flat_map(|l| &l.polyline)
                .all(|p| p.z_m == 0.0),
            "{}",
            path.display()
        );
        // 0.1 s steps.
        assert!(
            scene
                .timestamps_secs
                .windows(2)
                .all(|w| (w[1] - w[0] - 0.1).abs() < 1e-6)
        );
    }
}

#[test]
fn lossy_and_full_maps_and_timestamps() {
    let Some(dir) = real_dir() else { return };
    let lossy = read_scene(&dir.join("womd-reencoded/1c365f15b70ebdbf.tfrecord"));
    assert!(
        lossy
            .map
            .lanes
            .iter()
            .all(|l| l.lane_type == scbg_scene::LaneType::Undefined)
    );
    assert!(lossy.map.lanes.iter().all(|l| l.entry_lanes.is_empty()
        && l.exit_lanes.is_empty()
        && l.left_neighbors.is_empty()));
    assert!(
        lossy
            .map
            .road_lines
            .iter()
            .all(|l| l.line_type == scbg_scene::RoadLineType::Unknown)
    );
    for (i, t) in lossy.timestamps_secs.iter().enumerate() {
        assert!((t - 0.1 * i as f64).abs() < 1e-6);
    }
    let full = read_scene(&dir.join("womd-reencoded/2a1e44d405a6833f.tfrecord"));
    assert!(
        full.map
            .lanes
            .iter()
            .any(|l| l.lane_type != scbg_scene::LaneType::Undefined)
    );
    assert!(full.map.lanes.iter().any(|l| !l.exit_lanes.is_empty()));
    // Invalid states are honoured, whatever value they carry.
    let genuine = read_scene(&dir.join("womd/motion_data_one_scenario.tfrecord"));
    assert!(
        genuine
            .tracks
            .iter()
            .any(|t| t.states.iter().any(|s| !s.valid))
    );
    // The genuine file stores timestamps unpacked; they decode to 91 increasing values.
    assert!(genuine.timestamps_secs.windows(2).all(|w| w[1] > w[0]));
}

#[test]
fn labelled_pairs_of_interactive_scenarios() {
    let Some(dir) = real_dir() else { return };
    use scbg_features::{PairConfig, PairSource, PreparedScene, WindowConfig};
    for (id, a, b) in [
        ("1c365f15b70ebdbf", 1847, 1415),
        ("2a1e44d405a6833f", 490, 333),
    ] {
        let scene = read_scene(&dir.join(format!("womd-reencoded/{id}.tfrecord")));
        let p =
            PreparedScene::from_scene(&scene, &WindowConfig::default(), &PairConfig::default(), 4)
                .unwrap();
        let pair = p.pairs[0][0];
        assert_eq!(pair.source, PairSource::Labelled);
        assert_eq!((p.tracks[pair.first].id, p.tracks[pair.second].id), (a, b));
    }
    // A vehicle–pedestrian interest pair is not a vehicle pair: mining takes over.
    let scene = read_scene(&dir.join("womd-reencoded/2a173b334be3d32c.tfrecord"));
    let p = PreparedScene::from_scene(&scene, &WindowConfig::default(), &PairConfig::default(), 4)
        .unwrap();
    assert!(p.pairs[0].iter().all(|x| x.source == PairSource::Mined));
}

#[test]
fn bench_wosac_scores_the_reference_scenario() {
    let Some(dir) = real_dir() else { return };
    let text = crate::scbg_ok(&[
        "bench",
        "wosac",
        "--file",
        dir.join("womd/motion_data_one_scenario.tfrecord")
            .to_str()
            .unwrap(),
        "--repeats",
        "1",
    ]);
    assert!(text.contains("(50 sim agents)"), "{text}");
    assert!(text.contains("meta-metric 0.82663"), "{text}");
    assert!(text.contains("meta-metric 0.21769"), "{text}");
}

/// `scbg eval sim` of the generator in `gen_dir` on real files of three kinds — a nuScenes
/// scene (20 s, no road edge), a 20 s WOMD scene without an SDC or objects of interest, the
/// genuine 9.1 s WOMD scenario — and a file that is not WOMD: the long scenes are simulated
/// window by window with mined pairs, realism is scored where it applies and `n/a` elsewhere,
/// B's off-road is reported where the map has road edges, the bad file is left out by name and
/// reason, and no NaN is printed or written.
pub(crate) fn eval_sim_on_real_files(gen_dir: &str, dir: &std::path::Path) {
    let Some(real) = real_dir() else { return };
    let garbage = dir.join("not_womd.tfrecord");
    std::fs::write(&garbage, b"this is not a TFRecord file").unwrap();
    let files = [
        real.join("nuscenes-reencoded/scene-0061.tfrecord"),
        real.join("womd-reencoded/61fa872f2d274223.tfrecord"),
        real.join("womd/motion_data_one_scenario.tfrecord"),
        garbage.clone(),
    ];
    let out = dir.join("evalsim_real");
    let config = crate::settings(dir, "[closed_loop]\nwosac_quantiles = [0.5]\n");
    let mut args: Vec<String> = ["eval", "sim", "--model", gen_dir, "--split", "all"]
        .map(String::from)
        .to_vec();
    args.extend(["--scenes", "1000", "--wosac-scenes", "1"].map(String::from));
    args.push("--config".into());
    args.push(config.display().to_string());
    args.push("--out".into());
    args.push(out.display().to_string());
    args.push("--data".into());
    args.extend(files.iter().map(|f| f.display().to_string()));
    let text = crate::scbg_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!text.contains("NaN"), "{text}");
    assert!(text.contains("n/a"), "{text}");
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval_sim.json")).unwrap()).unwrap();
    // Windows of both long scenes and the genuine scenario itself.
    let sources = &eval["sources"];
    assert_eq!(sources["scenarios"], 3, "{eval}");
    assert!(sources["windows"].as_u64().unwrap() >= 2, "{eval}");
    assert!(sources["pairs"]["mined"].as_u64().unwrap() >= 2, "{eval}");
    let scenes = eval["scenes"].as_u64().unwrap();
    assert_eq!(scenes, sources["windows"].as_u64().unwrap() + 1, "{eval}");
    // Every quantile has B's off-road rate (the WOMD scenes have road edges).
    for row in eval["per_quantile"].as_array().unwrap() {
        assert!(row["b_offroad_rate"].is_number(), "{row}");
    }
    // Realism on the genuine scenario; not applicable to the others, each counted by reason.
    assert_eq!(eval["wosac_scbg"]["scenes"], 1, "{eval}");
    let skipped = eval["skipped"].as_object().unwrap();
    let count = |needle: &str| -> u64 {
        skipped
            .iter()
            .filter(|(k, _)| k.contains(needle))
            .map(|(_, v)| v.as_u64().unwrap())
            .sum()
    };
    assert_eq!(count("unreadable"), 1, "{eval}");
    assert!(count("WOSAC realism n/a") >= scenes - 1, "{eval}");
    let listed = eval["skipped_scenes"].as_array().unwrap();
    assert_eq!(
        listed.len() as u64,
        skipped.values().map(|v| v.as_u64().unwrap()).sum::<u64>()
    );
    assert!(
        listed
            .iter()
            .any(|s| s["scenario_id"].as_str().unwrap().contains("not_womd")),
        "{eval}"
    );
    assert!(text.contains("unreadable"), "{text}");
    // Nothing to simulate: the reasons, eval_sim.json still written, exit code 2.
    let only_bad: Vec<&str> = args[..args.len() - files.len()]
        .iter()
        .map(String::as_str)
        .chain([garbage.to_str().unwrap()])
        .collect();
    std::fs::remove_file(out.join("eval_sim.json")).unwrap();
    let failed = crate::scbg(&only_bad);
    let err = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(2), "{err}");
    assert!(
        err.contains("no scene could be simulated") && err.contains("unreadable"),
        "{err}"
    );
    assert!(!err.contains("NaN"), "{err}");
    let eval: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval_sim.json")).unwrap()).unwrap();
    assert_eq!(eval["scenes"], 0, "{eval}");
    assert!(
        eval["per_quantile"].as_array().unwrap().is_empty(),
        "{eval}"
    );
    assert!(eval["baselines"]["idm_only"]["a_avg_speed_mps"].is_null());
}
