//! SDXL's size and crop conditioning resolves once into the plan: every run of a model that
//! takes it holds the numbers it runs with (the drawn size and no crop unless asked), other
//! models keep their plans (and keys) as before and refuse a request for it, and bad numbers
//! name their field.

use super::*;
use crate::models::guided::{MAX_ORIGINAL_SIDE, SizeConditioning};

fn sdxl() -> ModelFacts {
    ModelFacts {
        size_conditioning: true,
        ..ModelFacts::stable_diffusion("sdxl")
    }
}

fn plan(req: &PlanRequest, facts: &ModelFacts) -> Result<TextPlan, SpecError> {
    Ok(resolve(req, Some(facts), &Limits::default())?.text.unwrap())
}

fn asking(s: SizeConditioningRequest) -> PlanRequest {
    PlanRequest {
        size_conditioning: Some(s),
        ..PlanRequest::text("a crown")
    }
}

#[test]
fn an_sdxl_plan_holds_the_drawn_size_unless_asked() {
    let t = plan(&PlanRequest::text("a crown"), &sdxl()).unwrap();
    let (w, h) = t.sample_dims();
    assert_eq!(t.size_conditioning, Some(SizeConditioning::drawn(w, h)));
    assert_eq!(
        t.sds_config().unwrap().size_conditioning,
        t.size_conditioning
    );

    // A wide canvas samples wide: the drawn size is the sample's, not the square's.
    let wide = PlanRequest {
        canvas: CanvasRequest {
            aspect: Some(crate::pipeline::Aspect::Wide16x9),
            ..CanvasRequest::default()
        },
        ..PlanRequest::text("a crown")
    };
    let t = plan(&wide, &sdxl()).unwrap();
    let (w, h) = t.sample_dims();
    assert!(w > h);
    assert_eq!(t.size_conditioning, Some(SizeConditioning::drawn(w, h)));

    // Asked: the given numbers, the rest completed.
    let t = plan(
        &asking(SizeConditioningRequest {
            original_width: Some(1024),
            crop_top: Some(32),
            ..Default::default()
        }),
        &sdxl(),
    )
    .unwrap();
    let (_, h) = t.sample_dims();
    let want = SizeConditioning {
        original_width: 1024,
        original_height: h,
        crop_left: 0,
        crop_top: 32,
    };
    assert_eq!(t.size_conditioning, Some(want));
    assert_eq!(t.sds_config().unwrap().size_conditioning, Some(want));
}

#[test]
fn other_models_keep_their_plans_and_refuse_size_conditioning() {
    let sd = ModelFacts::stable_diffusion("sd15");
    let t = plan(&PlanRequest::text("a crown"), &sd).unwrap();
    assert_eq!(t.size_conditioning, None);
    let json = serde_json::to_value(&t).unwrap();
    assert!(json.get("size_conditioning").is_none(), "{json}");
    let err = plan(&asking(SizeConditioningRequest::default()), &sd).unwrap_err();
    assert_eq!(err.field, "size_conditioning");
    assert!(err.reason.contains("sd15"), "{}", err.reason);
}

#[test]
fn bad_size_conditioning_names_its_field() {
    let err = |s: SizeConditioningRequest| plan(&asking(s), &sdxl()).unwrap_err().field;
    type Set = fn(&mut SizeConditioningRequest, u32);
    let big = MAX_ORIGINAL_SIDE + 1;
    let cases: [(Set, u32, &str); 4] = [
        (|s, v| s.original_width = Some(v), 0, "original_width"),
        (|s, v| s.original_height = Some(v), big, "original_height"),
        (|s, v| s.crop_left = Some(v), big, "crop_left"),
        (|s, v| s.crop_top = Some(v), big, "crop_top"),
    ];
    for (set, v, name) in cases {
        let mut s = SizeConditioningRequest::default();
        set(&mut s, v);
        assert_eq!(err(s), format!("size_conditioning.{name}"));
    }
    // The largest numbers are fine.
    let edge = SizeConditioningRequest {
        original_width: Some(MAX_ORIGINAL_SIDE),
        original_height: Some(1),
        crop_left: Some(MAX_ORIGINAL_SIDE),
        crop_top: Some(0),
    };
    assert!(plan(&asking(edge), &sdxl()).is_ok());
}

#[test]
fn time_ids_are_original_crop_and_target_height_first() {
    let s = SizeConditioning {
        original_width: 1024,
        original_height: 768,
        crop_left: 16,
        crop_top: 8,
    };
    // diffusers' `_get_add_time_ids`: original (h, w) + crop (top, left) + target (h, w).
    assert_eq!(s.time_ids((64, 32)), [768.0, 1024.0, 8.0, 16.0, 32.0, 64.0]);
    assert_eq!(
        SizeConditioning::drawn(56, 32).time_ids((56, 32)),
        [32.0, 56.0, 0.0, 0.0, 32.0, 56.0]
    );
}
