//! The fill paint resolves once into the plan: the trace's and SDS's settings follow it, flat
//! leaves the plan's JSON (and key) as before, and bad combinations name the field `fill`.

use super::*;
use crate::stages::styles::Style;

fn facts() -> ModelFacts {
    ModelFacts::paper("test")
}

fn with_fill(req: PlanRequest, fill: FillKind) -> PlanRequest {
    PlanRequest {
        vector: crate::vector::VectorOptions {
            fill,
            ..req.vector.clone()
        },
        ..req
    }
}

#[test]
fn a_gradient_fill_reaches_the_trace_and_sds() {
    let req = with_fill(PlanRequest::text("a crown"), FillKind::Radial);
    let t = resolve(&req, Some(&facts()), &Limits::default())
        .unwrap()
        .text
        .unwrap();
    assert_eq!(t.fill, FillKind::Radial);
    assert_eq!(t.trace_config().fill, FillKind::Radial);
    let sds = t.sds_config().unwrap();
    assert!(sds.trainable.paint && sds.trainable.points);
    assert_ne!(sds.schedules.paint_stops.lr(0), 0.0);
    // Flat: nothing trains the paint, and the plan's JSON has no `fill`.
    let flat = resolve(
        &PlanRequest::text("a crown"),
        Some(&facts()),
        &Limits::default(),
    )
    .unwrap();
    let ft = flat.text.as_ref().unwrap();
    assert_eq!(ft.trace_config().fill, FillKind::Flat);
    assert!(!ft.sds_config().unwrap().trainable.paint);
    assert!(!serde_json::to_string(&flat).unwrap().contains("fill"));
}

#[test]
fn a_vectorize_plan_takes_the_fill() {
    let req = PlanRequest {
        kind: JobKind::Vectorize,
        caption: None,
        ..with_fill(PlanRequest::text(""), FillKind::Linear)
    };
    let live = resolve(&req, None, &Limits::default())
        .unwrap()
        .vectorize
        .unwrap();
    assert_eq!(live.fill, FillKind::Linear);
    assert!(live.validate().is_ok());
    let back: LiveConfig = serde_json::from_str(&serde_json::to_string(&live).unwrap()).unwrap();
    assert_eq!(back, live);
}

#[test]
fn bad_combinations_name_the_fill_field() {
    let err = |req: PlanRequest| resolve(&req, Some(&facts()), &Limits::default()).unwrap_err();
    let pixel = PlanRequest {
        style: Style::PixelArt,
        ..with_fill(PlanRequest::text("a crown"), FillKind::Linear)
    };
    let e = err(pixel);
    assert_eq!(e.field, "fill");
    assert!(e.reason.contains("pixel_art"), "{}", e.reason);
    let mut palette = with_fill(PlanRequest::text("a crown"), FillKind::Radial);
    palette.vector.colors.colors = Some(4);
    let e = err(palette);
    assert_eq!(e.field, "fill");
    assert!(e.reason.contains("palette"), "{}", e.reason);
    // A vectorize job keeps the same rule, with or without a model (as openapi.yaml says).
    let sketch = PlanRequest {
        kind: JobKind::Vectorize,
        caption: None,
        style: Style::Sketch,
        ..with_fill(PlanRequest::text(""), FillKind::Linear)
    };
    for facts in [None, Some(facts())] {
        let e = resolve(&sketch, facts.as_ref(), &Limits::default()).unwrap_err();
        assert_eq!(e.field, "fill");
        assert!(e.reason.contains("sketch"), "{}", e.reason);
    }
}
