//! What a resolved [`TextPlan`] gives the stages: its sample and canvas sizes, and the LIVE and
//! SDS configurations it runs.

use super::{Limits, ModelFacts, PlanRequest, SpecError, TextPlan, check_text};
use crate::models::guided::{MAX_ORIGINAL_SIDE, SizeConditioning};
use crate::pipeline::canvas::SampleShape;
use crate::scene::Trainable;
use crate::stages::live::{LiveConfig, PathBudget};
use crate::stages::sds::{ReinitConfig, SdsConfig};
use crate::stages::styles::Style;
use crate::vector::fill::FillKind;
use serde::{Deserialize, Serialize};

impl TextPlan {
    /// `(width, height)` of the image the model samples, LIVE traces and SDS distils.
    pub fn sample_dims(&self) -> (u32, u32) {
        self.canvas.map_or((self.size, self.size), |c| {
            (c.sample_width, c.sample_height)
        })
    }

    /// `(width, height)` of the SVG's canvas.
    pub fn canvas_dims(&self) -> (u32, u32) {
        self.canvas
            .map_or((self.size, self.size), |c| (c.width, c.height))
    }

    /// The LIVE configuration that traces the run's starting image (the kept sample at
    /// [`TracePlan::size`], or a given image at the teacher's size): LIVE's own settings with
    /// the plan's path count, iterations, seed, snapshot period and colours.
    pub fn trace_config(&self) -> LiveConfig {
        LiveConfig {
            size: self.trace.size,
            budget: PathBudget::fixed(self.paths as usize),
            iters_per_stage: self.trace.iters,
            final_iters: self.trace.iters,
            seed: self.seeds.trace,
            snapshot_every: self.snapshot_every,
            colors: self.colors.clone(),
            fill: self.fill,
            ..LiveConfig::default()
        }
    }

    /// The score distillation this plan runs (`None`: `sd_live`, no distillation): the
    /// paper's settings for the style ([`SdsConfig::for_style`]) with the plan's prompt,
    /// guidance, timestep range, clipping, learning-rate scale, augmentation, re-init area,
    /// snapshot period and seed.
    pub fn sds_config(&self) -> Option<SdsConfig> {
        let sp = self.sds.as_ref()?;
        let paper = SdsConfig::for_style(self.style, "", sp.steps, self.size);
        let (w, h) = self.sample_dims();
        Some(SdsConfig {
            prompt: self.prompt.clone(),
            negative_prompt: self.negative_prompt.clone().unwrap_or_default(),
            size_conditioning: self.size_conditioning,
            t_min: sp.t_min,
            t_max: sp.t_max,
            t_max_end: sp.t_max_end,
            guidance: sp.guidance,
            grad_clip: sp.grad_clip,
            augment: paper
                .augment
                .filter(|_| sp.augment)
                .map(|a| a.with_output(w, h)),
            schedules: paper.schedules.scaled(sp.lr_scale),
            reinit: paper.reinit.map(|r| ReinitConfig {
                min_area: sp.reinit_min_area,
                ..r
            }),
            snapshot_every: self.snapshot_every,
            seed: self.seeds.sds,
            trainable: Trainable {
                paint: !self.fill.is_flat(),
                ..paper.trainable
            },
            ..paper
        })
    }
}

/// A gradient fill is for filled paths drawn freely: iconography (pixel art's cells, low
/// poly's flat polygons and the stroke styles keep their paint).
pub(super) fn check_fill_style(fill: FillKind, style: Style) -> Result<(), SpecError> {
    if fill.is_flat() || style == Style::Iconography {
        return Ok(());
    }
    let name = serde_json::to_value(style)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default();
    Err(SpecError::new(
        "fill",
        format!(
            "{} applies to style iconography only, not {name}",
            fill.name()
        ),
    ))
}

/// The shapes `req` is sampled at on `model`: pixel art draws its square grid.
pub(super) fn sample_shape(req: &PlanRequest, model: &ModelFacts) -> SampleShape {
    match req.style {
        crate::stages::styles::Style::PixelArt => SampleShape::Square,
        _ => model.sample_shape,
    }
}

/// `req`'s negative prompt, checked like a caption and refused for a model whose guidance
/// has no unconditional branch to put it in.
pub(super) fn negative_prompt(
    req: &PlanRequest,
    model: &ModelFacts,
    limits: &Limits,
) -> Result<Option<String>, SpecError> {
    let Some(n) = &req.negative_prompt else {
        return Ok(None);
    };
    check_text("negative_prompt", n, limits)?;
    if !model.negative_prompt {
        return Err(SpecError::new(
            "negative_prompt",
            format!(
                "{} has no classifier-free guidance with an unconditional branch to put a \
                 negative prompt in",
                model.name
            ),
        ));
    }
    Ok(Some(n.clone()))
}

/// The SDXL size and crop conditioning a caller asks for (SDXL paper §2.2): the original image
/// the drawn one stands for, and the crop's top-left corner in it. An omitted original side is
/// the drawn image's, an omitted crop coordinate 0 (diffusers' defaults); a model without
/// size conditioning refuses any.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizeConditioningRequest {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub original_width: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub original_height: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop_left: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop_top: Option<u32>,
}

impl SizeConditioningRequest {
    /// The request completed for an image drawn at `(width, height)` px and checked; an error
    /// names the field (`size_conditioning.original_width`, ...).
    pub fn resolve(&self, (width, height): (u32, u32)) -> Result<SizeConditioning, SpecError> {
        let max = MAX_ORIGINAL_SIDE;
        for (field, v, min) in [
            ("size_conditioning.original_width", self.original_width, 1),
            ("size_conditioning.original_height", self.original_height, 1),
            ("size_conditioning.crop_left", self.crop_left, 0),
            ("size_conditioning.crop_top", self.crop_top, 0),
        ] {
            if let Some(v) = v.filter(|v| !(min..=max).contains(v)) {
                return Err(SpecError::new(
                    field,
                    format!("must be between {min} and {max} px, got {v}"),
                ));
            }
        }
        // The drawn size is within the canvas limits, far below the largest original side.
        Ok(SizeConditioning {
            original_width: self.original_width.unwrap_or(width),
            original_height: self.original_height.unwrap_or(height),
            crop_left: self.crop_left.unwrap_or(0),
            crop_top: self.crop_top.unwrap_or(0),
        })
    }
}

/// The size conditioning of a run drawn at `drawn` px on `model`: resolved for a model that
/// takes it (the drawn size, no crop, unless asked), refused when asked of another.
pub(super) fn size_conditioning(
    req: &PlanRequest,
    model: &ModelFacts,
    drawn: (u32, u32),
) -> Result<Option<SizeConditioning>, SpecError> {
    match (&req.size_conditioning, model.size_conditioning) {
        (r, true) => r.unwrap_or_default().resolve(drawn).map(Some),
        (None, false) => Ok(None),
        (Some(_), false) => Err(SpecError::new(
            "size_conditioning",
            format!(
                "{} has no size conditioning (SDXL's original size and crop time ids)",
                model.name
            ),
        )),
    }
}
