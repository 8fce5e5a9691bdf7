//! The image ↔ latent map of a diffusion model ([`Codec`]): Stable Diffusion's VAE, TAESD (its
//! fast approximation, same latent space), or **pixel space** ([`PixelSpace`]) for models whose
//! UNet works on RGB directly (`docs/EMBEDDED.md`: a model directory without `vae/`).
//!
//! Every codec encodes images `[b, 3, H, W]` in `[0, 1]`, has an exact input-only VJP of its
//! encoder, and decodes latents back to `[0, 1]` images.

use super::taesd::Taesd;
use super::unet::UnetConfig;
use super::vae::AutoencoderKl;
use super::{ConfigIssue, ModelError, Result};
use candle_core::{DType, Device, Tensor};
use std::path::Path;

/// Which codec a model runs with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CodecKind {
    Vae,
    Taesd,
    Pixel,
}

impl CodecKind {
    pub fn as_str(self) -> &'static str {
        match self {
            CodecKind::Vae => "vae",
            CodecKind::Taesd => "taesd",
            CodecKind::Pixel => "pixel",
        }
    }
}

/// Pixel space: the "latent" of an image is the image area-resized to `size × size` and mapped
/// to `[-1, 1]` (`x·2 − 1`); decoding maps back (`(x+1)/2`, clamped) at `size × size`.
///
/// The area resize is PyTorch's `F.interpolate(mode="area")` (adaptive average pooling): output
/// pixel `i` of `n` averages input pixels `floor(i·N/n) .. ceil((i+1)·N/n)`. For integer ratios
/// (128 → 32) that is a plain box average. It is a linear map `R_h · X · R_wᵀ`, so its VJP is
/// the exact adjoint `R_hᵀ · dY · R_w`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PixelSpace {
    /// Latent side (the UNet's `sample_size`).
    pub size: usize,
}

/// `[n_out, n_in]` adaptive-average-pooling weights (rows sum to 1).
fn pool_matrix(n_out: usize, n_in: usize, device: &Device) -> Result<Tensor> {
    let mut m = vec![0.0f32; n_out * n_in];
    for i in 0..n_out {
        let start = i * n_in / n_out;
        let end = ((i + 1) * n_in).div_ceil(n_out).max(start + 1).min(n_in);
        let w = 1.0 / (end - start) as f32;
        for j in start..end {
            m[i * n_in + j] = w;
        }
    }
    Ok(Tensor::from_vec(m, (n_out, n_in), device)?)
}

impl PixelSpace {
    fn dims(&self, image: &Tensor) -> Result<(usize, usize)> {
        match image.dims4() {
            Ok((_, 3, h, w)) if h > 0 && w > 0 => Ok((h, w)),
            _ => Err(ModelError::InvalidInput(format!(
                "image must be [b, 3, h, w], got {:?}",
                image.dims()
            ))),
        }
    }

    /// Area resize of `[b, c, H, W]` to `[b, c, size, size]`.
    pub fn area_resize(&self, x: &Tensor) -> Result<Tensor> {
        let (h, w) = self.dims(x)?;
        let dev = x.device();
        let x = x.to_dtype(DType::F32)?;
        let rh = pool_matrix(self.size, h, dev)?;
        let rwt = pool_matrix(self.size, w, dev)?.t()?.contiguous()?;
        let y = x.broadcast_matmul(&rwt)?; // [b, c, H, s]
        Ok(rh.broadcast_matmul(&y)?) // [b, c, s, s]
    }

    /// Images `[b, 3, H, W]` in `[0, 1]` → `[b, 3, size, size]` in `[-1, 1]`.
    pub fn encode(&self, image: &Tensor) -> Result<Tensor> {
        Ok(((self.area_resize(image)? * 2.0)? - 1.0)?)
    }

    /// `J_encodeᵀ · d_latents` (the exact adjoint of the area resize, times 2).
    pub fn encode_vjp(&self, image: &Tensor, d_latents: &Tensor) -> Result<Tensor> {
        let (h, w) = self.dims(image)?;
        let (b, _, _, _) = image.dims4()?;
        super::check_latent_grad(d_latents, &[b, 3, self.size, self.size])?;
        let dev = image.device();
        let rht = pool_matrix(self.size, h, dev)?.t()?.contiguous()?;
        let rw = pool_matrix(self.size, w, dev)?;
        let d = (d_latents.to_dtype(DType::F32)? * 2.0)?;
        let d = d.broadcast_matmul(&rw)?; // [b, 3, s, W]
        Ok(rht.broadcast_matmul(&d)?.to_dtype(image.dtype())?) // [b, 3, H, W]
    }

    /// Latents `[b, 3, size, size]` → images in `[0, 1]` (clamped), at `size × size`.
    pub fn decode(&self, latents: &Tensor) -> Result<Tensor> {
        match latents.dims4() {
            Ok((_, 3, _, _)) => {}
            _ => {
                return Err(ModelError::InvalidInput(format!(
                    "pixel latents must be [b, 3, h, w], got {:?}",
                    latents.dims()
                )));
            }
        }
        Ok(((latents.to_dtype(DType::F32)? + 1.0)? * 0.5)?.clamp(0.0, 1.0)?)
    }
}

/// What [`Codec::encode_t`] keeps for [`Codec::encode_pullback`].
#[derive(Debug)]
pub enum EncodeTape {
    Vae(super::vae::EncodeTape),
    Taesd(super::taesd::EncodeTape),
    /// Pixel space is linear: its pullback needs only the image's shape (kept as the image).
    Pixel(Tensor),
}

impl EncodeTape {
    /// The codec that recorded this tape.
    pub fn kind(&self) -> CodecKind {
        match self {
            EncodeTape::Vae(_) => CodecKind::Vae,
            EncodeTape::Taesd(_) => CodecKind::Taesd,
            EncodeTape::Pixel(_) => CodecKind::Pixel,
        }
    }
}

/// The image ↔ latent map a model runs with.
#[derive(Debug)]
pub enum Codec {
    Vae(Box<AutoencoderKl>),
    Taesd(Box<Taesd>),
    Pixel(PixelSpace),
}

impl From<AutoencoderKl> for Codec {
    fn from(v: AutoencoderKl) -> Self {
        Codec::Vae(Box::new(v))
    }
}

impl From<Taesd> for Codec {
    fn from(t: Taesd) -> Self {
        Codec::Taesd(Box::new(t))
    }
}

impl From<PixelSpace> for Codec {
    fn from(p: PixelSpace) -> Self {
        Codec::Pixel(p)
    }
}

impl Codec {
    pub fn kind(&self) -> CodecKind {
        match self {
            Codec::Vae(_) => CodecKind::Vae,
            Codec::Taesd(_) => CodecKind::Taesd,
            Codec::Pixel(_) => CodecKind::Pixel,
        }
    }

    /// Channels of the latent.
    pub fn latent_channels(&self) -> usize {
        match self {
            Codec::Vae(v) => v.config.latent_channels,
            Codec::Taesd(t) => t.config.latent_channels,
            Codec::Pixel(_) => 3,
        }
    }

    /// Side of the latent of a square image of side `image_side`, or why that side is not
    /// accepted (autoencoders need a multiple of their downsampling factor).
    pub fn latent_side(&self, image_side: usize) -> std::result::Result<usize, ConfigIssue> {
        let down = match self {
            Codec::Vae(v) => v.config.downscale(),
            Codec::Taesd(t) => t.config.downscale(),
            Codec::Pixel(p) => {
                return if image_side == 0 {
                    Err(ConfigIssue::Inconsistent(
                        "image size must be positive".into(),
                    ))
                } else {
                    Ok(p.size)
                };
            }
        };
        if image_side == 0 || !image_side.is_multiple_of(down) {
            return Err(ConfigIssue::Inconsistent(format!(
                "image size {image_side} must be a positive multiple of the {}'s downsampling {down}",
                self.kind().as_str().to_uppercase()
            )));
        }
        Ok(image_side / down)
    }

    /// Images `[b, 3, H, W]` in `[0, 1]` → latents.
    pub fn encode(&self, image: &Tensor) -> Result<Tensor> {
        match self {
            Codec::Vae(v) => v.encode(image),
            Codec::Taesd(t) => t.encode(image),
            Codec::Pixel(p) => p.encode(image),
        }
    }

    /// `J_encodeᵀ · d_latents` with respect to the `[0, 1]` image (no weight gradients).
    pub fn encode_vjp(&self, image: &Tensor, d_latents: &Tensor) -> Result<Tensor> {
        let (_, tape) = self.encode_t(image)?;
        self.encode_pullback(tape, d_latents)
    }

    /// [`Self::encode`] that also keeps what [`Self::encode_pullback`] needs, so that encoding
    /// an image and pulling a latent gradient back to it cost one encoder forward pass.
    pub fn encode_t(&self, image: &Tensor) -> Result<(Tensor, EncodeTape)> {
        Ok(match self {
            Codec::Vae(v) => {
                let (z, t) = v.encode_t(image)?;
                (z, EncodeTape::Vae(t))
            }
            Codec::Taesd(t) => {
                let (z, tape) = t.encode_t(image)?;
                (z, EncodeTape::Taesd(tape))
            }
            Codec::Pixel(p) => (p.encode(image)?, EncodeTape::Pixel(image.clone())),
        })
    }

    /// `J_encodeᵀ · d_latents` at the image `tape` was recorded for (no weight gradients).
    pub fn encode_pullback(&self, tape: EncodeTape, d_latents: &Tensor) -> Result<Tensor> {
        match (self, tape) {
            (Codec::Vae(v), EncodeTape::Vae(t)) => v.encode_pullback(t, d_latents),
            (Codec::Taesd(m), EncodeTape::Taesd(t)) => m.encode_pullback(t, d_latents),
            (Codec::Pixel(p), EncodeTape::Pixel(image)) => p.encode_vjp(&image, d_latents),
            (c, t) => Err(ModelError::InvalidInput(format!(
                "a {} encoder tape cannot be pulled back through the {}",
                t.kind().as_str(),
                c.kind().as_str()
            ))),
        }
    }

    /// Latents → images in `[0, 1]` (pixel space: at the latent size).
    pub fn decode(&self, latents: &Tensor) -> Result<Tensor> {
        match self {
            Codec::Vae(v) => v.decode(latents),
            Codec::Taesd(t) => t.decode(latents),
            Codec::Pixel(p) => p.decode(latents),
        }
    }
}

/// Whether the diffusers directory `root` is a pixel-space model: no `vae/` folder and no
/// `"vae"` entry in its `model_index.json` (`docs/EMBEDDED.md`). A directory that names a VAE
/// but lacks the folder is a latent model with missing files (the VAE loader says which); a
/// path that is not a directory is not pixel space (the loader reports it).
pub fn is_pixel_space(root: &Path) -> Result<bool> {
    if !root.is_dir() || root.join("vae").exists() {
        return Ok(false);
    }
    let index = root.join("model_index.json");
    if !index.is_file() {
        return Ok(true);
    }
    let v: serde_json::Value = super::loader::read_config(&index)?;
    Ok(v.get("vae").is_none_or(|e| e.is_null()))
}

/// The pixel codec of a UNet, or why the UNet cannot work in pixel space.
pub fn pixel_space_for(unet: &UnetConfig, root: &Path) -> Result<PixelSpace> {
    let bad = |reason: String| ModelError::Unsupported {
        component: "unet",
        path: root.join("unet/config.json").display().to_string(),
        reason,
    };
    if unet.in_channels != 3 || unet.out_channels != 3 {
        return Err(bad(format!(
            "the model has no vae/ (a pixel-space model) but its UNet has {} input / {} output              channels; pixel space needs 3 and 3 (a latent model needs its vae/ folder)",
            unet.in_channels, unet.out_channels
        )));
    }
    match unet.sample_size {
        Some(s) if (1..=4096).contains(&s) => Ok(PixelSpace { size: s }),
        other => Err(bad(format!(
            "a pixel-space UNet needs sample_size in its config (1..=4096), got {other:?}"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(v: Vec<f32>, s: (usize, usize, usize, usize)) -> Tensor {
        Tensor::from_vec(v, s, &Device::Cpu).unwrap()
    }

    /// `Σ a·b` over all elements.
    fn dot(a: &Tensor, b: &Tensor) -> f32 {
        (a * b)
            .unwrap()
            .sum_all()
            .unwrap()
            .to_scalar::<f32>()
            .unwrap()
    }

    #[test]
    fn integer_ratio_is_a_box_average_and_non_integer_matches_adaptive_pooling() {
        let p = PixelSpace { size: 2 };
        let x: Vec<f32> = (0..3 * 16).map(|i| i as f32).collect();
        let y = p
            .area_resize(&t(x.clone(), (1, 3, 4, 4)))
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        // channel 0, top-left 2x2 block: 0, 1, 4, 5
        assert_eq!(y[0], 2.5);
        assert_eq!(y[3], (10.0 + 11.0 + 14.0 + 15.0) / 4.0);
        // 3 -> 2 (torch adaptive_avg_pool: bins [0,2) and [1,3))
        let p = PixelSpace { size: 2 };
        let y = p
            .area_resize(&t((0..27).map(|i| i as f32).collect(), (1, 3, 3, 3)))
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(y[0], (0.0 + 1.0 + 3.0 + 4.0) / 4.0);
        assert_eq!(y[3], (4.0 + 5.0 + 7.0 + 8.0) / 4.0);
    }

    #[test]
    fn vjp_is_the_exact_adjoint() {
        // <J v, d> == <v, Jᵀ d> for the linear part, on a non-integer ratio.
        let p = PixelSpace { size: 4 };
        let n = 3 * 7 * 6;
        let v: Vec<f32> = (0..n)
            .map(|i| ((i * 37 % 11) as f32) / 11.0 - 0.3)
            .collect();
        let d: Vec<f32> = (0..3 * 16)
            .map(|i| ((i * 13 % 7) as f32) / 7.0 - 0.5)
            .collect();
        let v = t(v, (1, 3, 7, 6));
        let d = t(d, (1, 3, 4, 4));
        let zero = Tensor::zeros((1, 3, 7, 6), DType::F32, &Device::Cpu).unwrap();
        let jv = (p.encode(&v).unwrap() - p.encode(&zero).unwrap()).unwrap();
        let lhs = dot(&jv, &d);
        let g = p.encode_vjp(&v, &d).unwrap();
        assert_eq!(g.dims(), &[1, 3, 7, 6]);
        let rhs = dot(&g, &v);
        assert!(
            (lhs - rhs).abs() < 1e-4 * lhs.abs().max(1.0),
            "{lhs} vs {rhs}"
        );
    }

    #[test]
    fn decode_inverts_encode_at_the_latent_size_and_clamps() {
        let p = PixelSpace { size: 2 };
        let x = t(vec![0.25; 12], (1, 3, 2, 2));
        let back = p.decode(&p.encode(&x).unwrap()).unwrap();
        let v = back.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(v.iter().all(|a| (a - 0.25).abs() < 1e-6));
        let big = p.decode(&t(vec![5.0; 12], (1, 3, 2, 2))).unwrap();
        assert!(
            big.flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
                .iter()
                .all(|a| *a == 1.0)
        );
        assert!(p.decode(&t(vec![0.0; 16], (1, 4, 2, 2))).is_err());
        assert!(p.encode(&t(vec![0.0; 16], (1, 4, 2, 2))).is_err());
    }
}
