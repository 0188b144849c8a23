//! What the integration tests share.

use scbg_features::{PairConfig, PreparedScene, WindowConfig};

/// Every scene of the shared real WOMD files, prepared with the default window and pair
/// settings (scenes that cannot be prepared left out); `None` without the real data
/// (`real_tfrecords` said why, and fails under CI).
pub fn real_prepared_scenes() -> Option<Vec<PreparedScene>> {
    let paths = scbg_womd::fixtures::real_tfrecords()?;
    let (window, pair) = (WindowConfig::default(), PairConfig::default());
    let mut out = Vec::new();
    for path in &paths {
        let file = scbg_womd::WomdFile::open(path).unwrap();
        for scene in file.scenes() {
            if let Ok(prepared) = PreparedScene::from_scene(&scene.unwrap(), &window, &pair, 4) {
                out.push(prepared);
            }
        }
    }
    Some(out)
}
