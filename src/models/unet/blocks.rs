//! The UNet's down, mid and up blocks (`CrossAttnDownBlock2D`/`DownBlock2D`,
//! `UNetMidBlock2DCrossAttn`, `CrossAttnUpBlock2D`/`UpBlock2D`) and their resamplers.

use super::config::{AttnArch, UnetArch};
use super::resnet::ResnetBlock2D;
use super::transformer::Transformer2DModel;
use crate::models::kernels::{self, pointwise};
use crate::models::nn::Conv2d;
use candle_core::Tensor;
use candle_nn::VarBuilder;

type R<T> = candle_core::Result<T>;

/// `Downsample2D`: a stride-2 3×3 convolution; with `downsample_padding = 0` the input is first
/// padded by one row and column at the bottom/right.
#[derive(Debug, Clone)]
pub struct Downsample2D {
    pub conv: Conv2d,
}

impl Downsample2D {
    pub fn load(vb: VarBuilder, c: usize, padding: usize) -> R<Self> {
        Ok(Self {
            conv: Conv2d::load(vb.pp("conv"), c, c, 3, 2, padding, true)?.forward_only()?,
        })
    }

    pub fn forward(&self, x: &Tensor) -> R<Tensor> {
        if self.conv.padding == 0 {
            self.conv.forward_padded(x, [0, 1, 0, 1])
        } else {
            self.conv.forward(x)
        }
    }
}

/// `Upsample2D`: nearest-neighbour resize (×2, or to the skip connection's size when the input
/// size is not a multiple of the UNet's total downsampling), then a 3×3 convolution.
#[derive(Debug, Clone)]
pub struct Upsample2D {
    pub conv: Conv2d,
}

impl Upsample2D {
    pub fn load(vb: VarBuilder, c: usize) -> R<Self> {
        Ok(Self {
            conv: Conv2d::load(vb.pp("conv"), c, c, 3, 1, 1, true)?.forward_only()?,
        })
    }

    pub fn forward(&self, x: &Tensor, size: (usize, usize)) -> R<Tensor> {
        let (b, c, h, w) = x.dims4()?;
        let (oh, ow) = size;
        let up = if kernels::applies(&[x]) {
            let y = kernels::with_f32(x, |xs| {
                pointwise::upsample_nearest(xs, h, w, oh, ow).map_err(kernels::err)
            })?;
            kernels::tensor(y, &[b, c, oh, ow])?
        } else {
            x.upsample_nearest2d(oh, ow)?
        };
        self.conv.forward(&up)
    }
}

fn resnets(
    vb: &VarBuilder,
    arch: &UnetArch,
    chans: impl Iterator<Item = (usize, usize)>,
    scale: f64,
) -> R<Vec<ResnetBlock2D>> {
    chans
        .enumerate()
        .map(|(j, (ci, co))| {
            ResnetBlock2D::load(
                vb.pp(format!("resnets.{j}")),
                (ci, co, arch.time_embed_dim()),
                arch.groups,
                arch.eps,
                scale,
            )
        })
        .collect()
}

fn attentions(
    vb: &VarBuilder,
    arch: &UnetArch,
    attn: Option<AttnArch>,
    c: usize,
    count: usize,
) -> R<Vec<Transformer2DModel>> {
    let Some(a) = attn else {
        return Ok(Vec::new());
    };
    (0..count)
        .map(|j| {
            Transformer2DModel::load(
                vb.pp(format!("attentions.{j}")),
                c,
                (a.heads, a.layers),
                arch.cross_attention_dim,
                arch.groups,
                arch.upcast_attention,
            )
        })
        .collect()
}

/// A down block: `layers_per_block` × (resnet, transformer if any), then a downsampler (all
/// but the last level). Every intermediate output is a skip connection.
#[derive(Debug, Clone)]
pub struct DownBlock {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Transformer2DModel>,
    pub downsampler: Option<Downsample2D>,
}

impl DownBlock {
    pub fn load(vb: VarBuilder, arch: &UnetArch, level: usize) -> R<Self> {
        let lv = arch.levels[level];
        let ci = if level == 0 {
            arch.levels[0].channels
        } else {
            arch.levels[level - 1].channels
        };
        let co = lv.channels;
        let n = arch.layers_per_block;
        let chans = (0..n).map(|j| (if j == 0 { ci } else { co }, co));
        let downsampler = if level + 1 < arch.levels.len() {
            Some(Downsample2D::load(
                vb.pp("downsamplers.0"),
                co,
                arch.downsample_padding,
            )?)
        } else {
            None
        };
        Ok(Self {
            resnets: resnets(&vb, arch, chans, 1.0)?,
            attentions: attentions(&vb, arch, lv.down_attn, co, n)?,
            downsampler,
        })
    }

    pub fn forward(
        &self,
        mut h: Tensor,
        temb: &Tensor,
        ctx: &Tensor,
        skips: &mut Vec<Tensor>,
    ) -> R<Tensor> {
        for (j, r) in self.resnets.iter().enumerate() {
            h = r.forward(&h, temb)?;
            if let Some(a) = self.attentions.get(j) {
                h = a.forward(&h, ctx)?;
            }
            skips.push(h.clone());
        }
        if let Some(d) = &self.downsampler {
            h = d.forward(&h)?;
            skips.push(h.clone());
        }
        Ok(h)
    }
}

/// `UNetMidBlock2DCrossAttn`: resnet, transformer(s), resnet.
#[derive(Debug, Clone)]
pub struct MidBlock {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Transformer2DModel>,
}

impl MidBlock {
    pub fn load(vb: VarBuilder, arch: &UnetArch) -> R<Self> {
        let c = arch.levels[arch.levels.len() - 1].channels;
        Ok(Self {
            resnets: resnets(
                &vb,
                arch,
                [(c, c), (c, c)].into_iter(),
                arch.mid_block_scale_factor,
            )?,
            attentions: attentions(&vb, arch, Some(arch.mid), c, 1)?,
        })
    }

    pub fn forward(&self, h: &Tensor, temb: &Tensor, ctx: &Tensor) -> R<Tensor> {
        let mut h = self.resnets[0].forward(h, temb)?;
        for a in &self.attentions {
            h = a.forward(&h, ctx)?;
        }
        self.resnets[1].forward(&h, temb)
    }
}

/// An up block: `layers_per_block + 1` × (concatenate a skip, resnet, transformer if any),
/// then an upsampler (all but the last up block).
#[derive(Debug, Clone)]
pub struct UpBlock {
    pub resnets: Vec<ResnetBlock2D>,
    pub attentions: Vec<Transformer2DModel>,
    pub upsampler: Option<Upsample2D>,
}

impl UpBlock {
    /// Up block `i` (level `n − 1 − i`).
    pub fn load(vb: VarBuilder, arch: &UnetArch, i: usize) -> R<Self> {
        let n = arch.levels.len();
        let level = n - 1 - i;
        let rev = |j: usize| arch.levels[n - 1 - j].channels;
        let (prev, out, input) = (rev(i.saturating_sub(1)), rev(i), rev((i + 1).min(n - 1)));
        let layers = arch.layers_per_block + 1;
        let chans = (0..layers).map(|j| {
            let skip = if j == layers - 1 { input } else { out };
            let res_in = if j == 0 { prev } else { out };
            (res_in + skip, out)
        });
        let upsampler = if i + 1 < n {
            Some(Upsample2D::load(vb.pp("upsamplers.0"), out)?)
        } else {
            None
        };
        Ok(Self {
            resnets: resnets(&vb, arch, chans, 1.0)?,
            attentions: attentions(&vb, arch, arch.levels[level].up_attn, out, layers)?,
            upsampler,
        })
    }

    /// `to_skip_size`: the upsampler resizes to the next skip connection's size instead of ×2
    /// (diffusers does so when the input size is not a multiple of the total downsampling).
    pub fn forward(
        &self,
        mut h: Tensor,
        temb: &Tensor,
        ctx: &Tensor,
        skips: &mut Vec<Tensor>,
        to_skip_size: bool,
    ) -> R<Tensor> {
        for (j, r) in self.resnets.iter().enumerate() {
            let Some(s) = skips.pop() else {
                candle_core::bail!("unet: skip connections exhausted");
            };
            h = r.forward(&Tensor::cat(&[&h, &s], 1)?, temb)?;
            if let Some(a) = self.attentions.get(j) {
                h = a.forward(&h, ctx)?;
            }
        }
        if let Some(u) = &self.upsampler {
            let (_, _, hh, ww) = h.dims4()?;
            let size = match (to_skip_size, skips.last()) {
                (true, Some(s)) => {
                    let (_, _, sh, sw) = s.dims4()?;
                    (sh, sw)
                }
                _ => (2 * hh, 2 * ww),
            };
            h = u.forward(&h, size)?;
        }
        Ok(h)
    }
}
