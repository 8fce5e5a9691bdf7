//! The SDS stage's tuning flags, shared by `generate` and `eval` (one set of flags, one
//! [`Tuning`] they turn into; the plan resolves what is left to the preset and the model).

use crate::pipeline::Tuning;

#[derive(clap::Args, Debug, Clone, Default)]
pub struct SdsTuningArgs {
    /// Teacher input size in pixels (the SVG is written at this width) [default: the preset's].
    #[arg(long)]
    pub size: Option<u32>,
    /// SDS classifier-free guidance scale [default: the model's (`_sds_guidance` in its
    /// model_index.json), 100 as in the paper for Stable Diffusion and the test teacher].
    #[arg(long)]
    pub guidance: Option<f32>,
    /// Smallest timestep drawn [default: 50].
    #[arg(long)]
    pub t_min: Option<usize>,
    /// Largest timestep drawn (at the start, see `--t-max-end`) [default: 950].
    #[arg(long)]
    pub t_max: Option<usize>,
    /// Anneal the largest timestep linearly to this value by the last step.
    #[arg(long)]
    pub t_max_end: Option<usize>,
    /// Clip each parameter group's gradient to this L2 norm.
    #[arg(long)]
    pub grad_clip: Option<f32>,
    /// Multiply every SDS learning rate of the style's schedule by this (0 < x <= 100) [default: 1].
    #[arg(long)]
    pub lr_scale: Option<f32>,
    /// Also re-initialise closed paths whose area is below this many px² (iconography) [default:
    /// the paper's 64 px² at 512 px when the run starts from a sample, image or SVG].
    #[arg(long)]
    pub reinit_min_area: Option<f32>,
    /// Turn off the random perspective + crop augmentation (from-scratch runs use it).
    #[arg(long)]
    pub no_augment: bool,
}

impl SdsTuningArgs {
    /// The flags as the plan's [`Tuning`] (`snapshot_every` is the caller's; no LIVE override).
    pub fn tuning(&self, snapshot_every: Option<u32>) -> Tuning {
        Tuning {
            size: self.size,
            guidance: self.guidance,
            t_min: self.t_min,
            t_max: self.t_max,
            t_max_end: self.t_max_end,
            grad_clip: self.grad_clip,
            lr_scale: self.lr_scale,
            reinit_min_area: self.reinit_min_area,
            augment: self.no_augment.then_some(false),
            snapshot_every,
            live: None,
        }
    }
}
