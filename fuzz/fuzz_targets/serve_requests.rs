//! Fuzzes the HTTP server's request decoding: every JSON body type (with the checks the
//! handlers apply before any inference) and the scenario upload decoder.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scbg_serve::api::{
    CourtesyAsk, CourtesyRequest, CreateSession, GenerateRequest, OpenScenario, StepRequest,
};

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = serde_json::from_slice::<GenerateRequest>(data) {
        let _ = CourtesyAsk {
            quantile: r.quantile,
            psi: r.psi,
        }
        .to_courtesy();
    }
    let _ = serde_json::from_slice::<CourtesyRequest>(data);
    if let Ok(s) = serde_json::from_slice::<CreateSession>(data) {
        for c in &s.controlled {
            let _ = CourtesyAsk {
                quantile: c.quantile,
                psi: c.psi,
            }
            .to_courtesy();
        }
    }
    let _ = serde_json::from_slice::<StepRequest>(data);
    if let Ok(o) = serde_json::from_slice::<OpenScenario>(data) {
        let _ = std::path::Path::new(&o.file).components().count();
    }
    // The upload path: a TFRecord file or one bare Scenario message.
    let _ = scbg::data::scenes_from_bytes(data.to_vec());
});
