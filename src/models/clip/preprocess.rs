//! Image preprocessing exactly as the reference `CLIPImageProcessor` (PIL backend) and
//! OpenCLIP's torchvision transform: composite over white, quantise to 8 bits, resize the
//! shortest side with PIL's bicubic filter (reproduced here in PIL's fixed-point arithmetic),
//! centre crop, scale to [0, 1], normalise with the OpenAI mean/std.

use super::ClipError;
use crate::image::Image;
use std::path::Path;

/// OpenAI CLIP normalisation mean (RGB).
pub const OPENAI_MEAN: [f32; 3] = [0.481_454_66, 0.457_827_5, 0.408_210_73];
/// OpenAI CLIP normalisation std (RGB).
#[allow(clippy::excessive_precision)] // the reference values, digit for digit
pub const OPENAI_STD: [f32; 3] = [0.268_629_54, 0.261_302_58, 0.275_777_11];

/// How the centre-crop offset is rounded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CropRounding {
    /// `(size - crop) // 2`: transformers' `center_crop`.
    Floor,
    /// `round((size - crop) / 2)` (half to even): torchvision's `CenterCrop` (OpenCLIP).
    RoundHalfEven,
}

/// Preprocessing parameters (`preprocessor_config.json`).
#[derive(Debug, Clone, PartialEq)]
pub struct PreprocessConfig {
    /// Target of the shortest side (`size.shortest_edge`), or `None` to resize to exactly
    /// `resize_hw` when that is set.
    pub shortest_edge: Option<u32>,
    /// Exact `(height, width)` resize when `size` is given as height/width.
    pub resize_hw: Option<(u32, u32)>,
    pub do_resize: bool,
    pub do_center_crop: bool,
    /// `(height, width)`.
    pub crop: (u32, u32),
    pub do_rescale: bool,
    pub rescale_factor: f32,
    pub do_normalize: bool,
    pub mean: [f32; 3],
    pub std: [f32; 3],
    pub crop_rounding: CropRounding,
}

impl PreprocessConfig {
    /// The reference defaults for a model with square inputs of `image_size`.
    pub fn for_image_size(image_size: u32) -> Self {
        Self {
            shortest_edge: Some(image_size),
            resize_hw: None,
            do_resize: true,
            do_center_crop: true,
            crop: (image_size, image_size),
            do_rescale: true,
            rescale_factor: 1.0 / 255.0,
            do_normalize: true,
            mean: OPENAI_MEAN,
            std: OPENAI_STD,
            crop_rounding: CropRounding::Floor,
        }
    }

    /// Reads `preprocessor_config.json`; falls back to [`Self::for_image_size`] for every field
    /// it does not set. Only bicubic resampling (`resample: 3`) is supported.
    pub fn from_file(path: &Path, image_size: u32) -> Result<Self, ClipError> {
        let err = |m: String| ClipError::Config(format!("{}: {m}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| ClipError::io(path, e))?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
        let mut c = Self::for_image_size(image_size);
        let as_u32 = |x: &serde_json::Value| x.as_u64().map(|n| n as u32);
        if let Some(s) = v.get("size") {
            if let Some(n) = as_u32(s) {
                c.shortest_edge = Some(n);
            } else if let Some(n) = s.get("shortest_edge").and_then(as_u32) {
                c.shortest_edge = Some(n);
            } else if let (Some(h), Some(w)) = (
                s.get("height").and_then(as_u32),
                s.get("width").and_then(as_u32),
            ) {
                c.shortest_edge = None;
                c.resize_hw = Some((h, w));
            } else {
                return Err(err(format!("unsupported size {s}")));
            }
        }
        if let Some(s) = v.get("crop_size") {
            if let Some(n) = as_u32(s) {
                c.crop = (n, n);
            } else if let (Some(h), Some(w)) = (
                s.get("height").and_then(as_u32),
                s.get("width").and_then(as_u32),
            ) {
                c.crop = (h, w);
            } else {
                return Err(err(format!("unsupported crop_size {s}")));
            }
        }
        let flag = |name: &str, d: bool| v.get(name).and_then(|b| b.as_bool()).unwrap_or(d);
        c.do_resize = flag("do_resize", true);
        c.do_center_crop = flag("do_center_crop", true);
        c.do_rescale = flag("do_rescale", true);
        c.do_normalize = flag("do_normalize", true);
        if let Some(f) = v.get("rescale_factor").and_then(|f| f.as_f64()) {
            c.rescale_factor = f as f32;
        }
        let triple = |name: &str| -> Result<Option<[f32; 3]>, ClipError> {
            match v.get(name) {
                None | Some(serde_json::Value::Null) => Ok(None),
                Some(a) => {
                    let xs: Vec<f32> = serde_json::from_value(a.clone())
                        .map_err(|e| err(format!("{name}: {e}")))?;
                    match xs.as_slice() {
                        [a, b, c] => Ok(Some([*a, *b, *c])),
                        [a] => Ok(Some([*a; 3])),
                        _ => Err(err(format!("{name} must have 3 values"))),
                    }
                }
            }
        };
        if let Some(m) = triple("image_mean")? {
            c.mean = m;
        }
        if let Some(s) = triple("image_std")? {
            c.std = s;
        }
        if let Some(r) = v.get("resample").and_then(|r| r.as_u64())
            && r != 3
        {
            return Err(err(format!(
                "resample {r} is not supported (only 3 = bicubic)"
            )));
        }
        Ok(c)
    }

    /// Output `(height, width)`.
    pub fn output_size(&self) -> (u32, u32) {
        self.crop
    }
}

/// An 8-bit RGB image (row-major, 3 bytes per pixel).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rgb8 {
    pub width: u32,
    pub height: u32,
    pub data: Vec<u8>,
}

/// Composites a premultiplied image over white and rounds to 8 bits (half up).
pub fn rgb8_over_white(img: &Image) -> Rgb8 {
    let mut data = Vec::with_capacity(img.len_pixels() * 3);
    for px in img.data.chunks_exact(4) {
        let a = px[3];
        for &c in &px[..3] {
            let v = c + (1.0 - a);
            data.push((v * 255.0 + 0.5).floor().clamp(0.0, 255.0) as u8);
        }
    }
    Rgb8 {
        width: img.width,
        height: img.height,
        data,
    }
}

const PRECISION_BITS: u32 = 32 - 8 - 2;

fn bicubic(x: f64) -> f64 {
    const A: f64 = -0.5;
    let x = x.abs();
    if x < 1.0 {
        ((A + 2.0) * x - (A + 3.0)) * x * x + 1.0
    } else if x < 2.0 {
        (((x - 5.0) * x + 8.0) * x - 4.0) * A
    } else {
        0.0
    }
}

/// PIL's `precompute_coeffs` + `normalize_coeffs_8bpc` for a full-box resize.
fn coeffs(in_size: u32, out_size: u32) -> Vec<(usize, Vec<i32>)> {
    let scale = f64::from(in_size) / f64::from(out_size);
    let filterscale = scale.max(1.0);
    let support = 2.0 * filterscale;
    let ss = 1.0 / filterscale;
    (0..out_size)
        .map(|xx| {
            let center = (f64::from(xx) + 0.5) * scale;
            let xmin = ((center - support + 0.5) as i64).max(0);
            let xmax = ((center + support + 0.5) as i64).min(i64::from(in_size)) - xmin;
            let w: Vec<f64> = (0..xmax.max(0))
                .map(|x| bicubic((x as f64 + xmin as f64 - center + 0.5) * ss))
                .collect();
            let ww: f64 = w.iter().sum();
            let k = w
                .iter()
                .map(|&v| {
                    let v = if ww != 0.0 { v / ww } else { v };
                    let f = v * f64::from(1u32 << PRECISION_BITS);
                    if v < 0.0 {
                        (-0.5 + f) as i32
                    } else {
                        (0.5 + f) as i32
                    }
                })
                .collect();
            (xmin as usize, k)
        })
        .collect()
}

fn clip8(v: i32) -> u8 {
    (v >> PRECISION_BITS).clamp(0, 255) as u8
}

/// `PIL.Image.resize(size, Image.BICUBIC)` on an RGB image, bit-exact (horizontal pass, then
/// vertical, 22-bit fixed point).
pub fn resize_bicubic_pil(src: &Rgb8, out_w: u32, out_h: u32) -> Rgb8 {
    let (w, h) = (src.width as usize, src.height as usize);
    let mut cur = src.clone();
    if out_w != src.width {
        let k = coeffs(src.width, out_w);
        let ow = out_w as usize;
        let mut data = vec![0u8; ow * h * 3];
        for y in 0..h {
            for (xx, (xmin, kk)) in k.iter().enumerate() {
                for c in 0..3 {
                    let mut ss: i32 = 1 << (PRECISION_BITS - 1);
                    for (j, &kv) in kk.iter().enumerate() {
                        ss += i32::from(cur.data[(y * w + xmin + j) * 3 + c]) * kv;
                    }
                    data[(y * ow + xx) * 3 + c] = clip8(ss);
                }
            }
        }
        cur = Rgb8 {
            width: out_w,
            height: src.height,
            data,
        };
    }
    if out_h != src.height {
        let k = coeffs(src.height, out_h);
        let cw = cur.width as usize;
        let mut data = vec![0u8; cw * out_h as usize * 3];
        for (yy, (ymin, kk)) in k.iter().enumerate() {
            for x in 0..cw {
                for c in 0..3 {
                    let mut ss: i32 = 1 << (PRECISION_BITS - 1);
                    for (j, &kv) in kk.iter().enumerate() {
                        ss += i32::from(cur.data[((ymin + j) * cw + x) * 3 + c]) * kv;
                    }
                    data[(yy * cw + x) * 3 + c] = clip8(ss);
                }
            }
        }
        cur = Rgb8 {
            width: cur.width,
            height: out_h,
            data,
        };
    }
    cur
}

/// Size after resizing the shortest side to `short` (transformers / torchvision rule: the long
/// side is `int(short * long / short_in)`).
pub fn shortest_edge_size(width: u32, height: u32, short: u32) -> (u32, u32) {
    if width <= height {
        let long = (f64::from(short) * f64::from(height) / f64::from(width)) as u32;
        (short, long)
    } else {
        let long = (f64::from(short) * f64::from(width) / f64::from(height)) as u32;
        (long, short)
    }
}

fn crop_offset(size: u32, crop: u32, r: CropRounding) -> i64 {
    let d = i64::from(size) - i64::from(crop);
    match r {
        CropRounding::Floor => d.div_euclid(2),
        CropRounding::RoundHalfEven => (d as f64 / 2.0).round_ties_even() as i64,
    }
}

/// Centre crop to `(height, width)`; pads with zeros where the image is smaller.
pub fn center_crop(src: &Rgb8, crop_h: u32, crop_w: u32, r: CropRounding) -> Rgb8 {
    let top = crop_offset(src.height, crop_h, r);
    let left = crop_offset(src.width, crop_w, r);
    let mut data = vec![0u8; crop_h as usize * crop_w as usize * 3];
    for y in 0..crop_h as i64 {
        let sy = y + top;
        if sy < 0 || sy >= i64::from(src.height) {
            continue;
        }
        for x in 0..crop_w as i64 {
            let sx = x + left;
            if sx < 0 || sx >= i64::from(src.width) {
                continue;
            }
            let s = ((sy as usize) * src.width as usize + sx as usize) * 3;
            let d = ((y as usize) * crop_w as usize + x as usize) * 3;
            data[d..d + 3].copy_from_slice(&src.data[s..s + 3]);
        }
    }
    Rgb8 {
        width: crop_w,
        height: crop_h,
        data,
    }
}

/// Runs the whole pipeline on one image; returns CHW `f32` values of the output size.
pub fn preprocess(img: &Image, cfg: &PreprocessConfig) -> Result<Vec<f32>, ClipError> {
    if img.width == 0 || img.height == 0 {
        return Err(ClipError::Input("empty image".into()));
    }
    let mut rgb = rgb8_over_white(img);
    if cfg.do_resize {
        let (w, h) = match (cfg.shortest_edge, cfg.resize_hw) {
            (Some(s), _) => shortest_edge_size(rgb.width, rgb.height, s),
            (None, Some((h, w))) => (w, h),
            (None, None) => (rgb.width, rgb.height),
        };
        if w == 0 || h == 0 {
            return Err(ClipError::Input(format!(
                "image {}x{} is too thin to resize",
                img.width, img.height
            )));
        }
        rgb = resize_bicubic_pil(&rgb, w, h);
    }
    if cfg.do_center_crop {
        rgb = center_crop(&rgb, cfg.crop.0, cfg.crop.1, cfg.crop_rounding);
    }
    let (w, h) = (rgb.width as usize, rgb.height as usize);
    let mut out = vec![0f32; 3 * w * h];
    for c in 0..3 {
        for i in 0..w * h {
            let mut v = f32::from(rgb.data[i * 3 + c]);
            if cfg.do_rescale {
                v = (f64::from(v) * f64::from(cfg.rescale_factor)) as f32;
            }
            if cfg.do_normalize {
                v = (v - cfg.mean[c]) / cfg.std[c];
            }
            out[c * w * h + i] = v;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identity_size_is_untouched_and_constant_images_stay_constant() {
        let src = Rgb8 {
            width: 5,
            height: 4,
            data: (0..60).map(|i| (i * 4) as u8).collect(),
        };
        assert_eq!(resize_bicubic_pil(&src, 5, 4), src);
        let flat = Rgb8 {
            width: 17,
            height: 9,
            data: vec![77; 17 * 9 * 3],
        };
        let r = resize_bicubic_pil(&flat, 6, 13);
        assert!(r.data.iter().all(|&v| v == 77));
    }

    #[test]
    fn shortest_edge_and_crop_offsets() {
        assert_eq!(shortest_edge_size(48, 40, 32), (38, 32));
        assert_eq!(shortest_edge_size(37, 53, 32), (32, 45));
        assert_eq!(crop_offset(45, 32, CropRounding::Floor), 6);
        assert_eq!(crop_offset(35, 32, CropRounding::Floor), 1);
        assert_eq!(crop_offset(35, 32, CropRounding::RoundHalfEven), 2);
    }

    #[test]
    fn transparent_pixels_become_white() {
        let img = Image::new(2, 2);
        let rgb = rgb8_over_white(&img);
        assert!(rgb.data.iter().all(|&v| v == 255));
    }
}
