//! The embedded model steered toward a caption's colour and objects (`_colour_steer`,
//! docs/embedded/COLOUR.md): the SVG of "a blue cat" is blue, the same seed draws the same SVG,
//! and a two-object caption composes one icon of each (or says it cannot, from noise). Needs the
//! MiniLM weights and the retrieval index (`vectorfusion setup`; CI runs it); SKIP without.

mod common;

use std::path::{Path, PathBuf};
use vectorfusion::caption::Hue;
use vectorfusion::caption::colour::dominant;
use vectorfusion::models::bert::weights::MiniLmLocations;
use vectorfusion::pipeline::{Method, PlanRequest, Preset};
use vectorfusion::retrieval::RetrievalLocations;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("models/vf-icon")
}

/// Whether the MiniLM weights and the retrieval index are there (else the test SKIPs).
fn installed(test: &str) -> bool {
    let why = MiniLmLocations::from_env()
        .ensure(false)
        .err()
        .map(|e| e.to_string())
        .or_else(|| {
            RetrievalLocations::from_env()
                .load(&root())
                .err()
                .map(|e| e.to_string())
        });
    if let Some(why) = why {
        common::skip(test, &why);
        return false;
    }
    true
}

fn request(caption: &str, retrieval: bool) -> PlanRequest {
    PlanRequest {
        method: Method::SdLiveSds,
        preset: Preset::Draft,
        paths: Some(8),
        steps: Some(4),
        samples: Some(2),
        seed: 5,
        retrieval,
        ..PlanRequest::text(caption)
    }
}

#[test]
fn a_blue_cat_is_blue_and_the_same_seed_draws_it_again() {
    if !installed("a_blue_cat_is_blue_and_the_same_seed_draws_it_again") {
        return;
    }
    let m = common::runs::executor(root(), Some(root().join("scorer")));
    for retrieval in [true, false] {
        let req = request("a blue cat", retrieval);
        let plan = common::runs::plan(&m, &req);
        let cp = plan.text.as_ref().and_then(|t| t.caption.as_ref()).unwrap();
        assert_eq!(cp.colour().map(|c| c.hue), Some(Hue::Blue));
        let a = common::runs::run(&m, &req).unwrap();
        let b = common::runs::run(&m, &req).unwrap();
        assert_eq!(a.svg, b.svg, "retrieval {retrieval}: not deterministic");
        let render = vectorfusion::raster::render(&a.scene);
        assert_eq!(dominant(&render), Some(Hue::Blue), "retrieval {retrieval}");
        let detail = serde_json::to_value(&a.report).unwrap();
        assert_eq!(detail["caption"]["colour"]["hue"], "blue", "{detail}");
        if retrieval {
            // Retrieved for the object, not the colour.
            assert_eq!(detail["caption"]["retrieved_for"][0], "cat", "{detail}");
        }
    }
}

#[test]
fn two_objects_are_composed_or_reported() {
    if !installed("two_objects_are_composed_or_reported") {
        return;
    }
    let m = common::runs::executor(root(), Some(root().join("scorer")));
    let out = common::runs::run(&m, &request("a cat wearing a hat", true)).unwrap();
    let detail = serde_json::to_value(&out.report).unwrap();
    let c = &detail["caption"];
    assert_eq!(c["objects"], serde_json::json!(["cat", "hat"]), "{detail}");
    assert_eq!(
        c["composed_with"].as_array().map(Vec::len),
        Some(2),
        "{detail}"
    );
    assert!(out.svg.contains("composed with the icon"), "{}", out.svg);
    // From noise the model cannot compose: the report says so.
    let out = common::runs::run(&m, &request("a cat wearing a hat", false)).unwrap();
    let detail = serde_json::to_value(&out.report).unwrap();
    let limits = detail["caption"]["limits"].as_array().unwrap();
    assert!(
        limits[0].as_str().unwrap().contains("two things"),
        "{detail}"
    );
}
