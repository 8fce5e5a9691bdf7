//! RGBA `f32` image buffers, PNG/JPEG in and out, and image metrics.
//!
//! Pixels are row-major, 4 channels, **premultiplied** alpha, values in `[0, 1]`. With an opaque
//! background (the usual case) premultiplied and straight alpha coincide.

pub mod ops;
pub mod ssim;

use std::path::Path;

/// Why an image could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("cannot decode image: {0}")]
    Decode(String),
    #[error("cannot encode image: {0}")]
    Encode(String),
    #[error("image is {width}x{height}, larger than the limit of {limit} pixels per side")]
    TooLarge { width: u32, height: u32, limit: u32 },
    #[error("image has zero width or height")]
    Empty,
    #[error("I/O error on {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
}

/// Largest image side we decode (guards memory against hostile inputs).
pub const MAX_DECODE_SIDE: u32 = 8192;

/// A premultiplied RGBA `f32` image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    /// `4 * width * height` values, row-major RGBA, premultiplied.
    pub data: Vec<f32>,
}

impl Image {
    /// A transparent image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![0.0; 4 * width as usize * height as usize],
        }
    }

    /// The RGB planes (`[3 * H * W]`, channel-major) of this image composited over white:
    /// `c + (1 - a)` per premultiplied channel, the input layout of the diffusion models.
    pub fn planar_rgb_over_white(&self) -> Vec<f32> {
        let n = (self.width * self.height) as usize;
        let mut planar = vec![0.0f32; 3 * n];
        for (i, p) in self.data.chunks_exact(4).enumerate().take(n) {
            for c in 0..3 {
                planar[c * n + i] = p[c] + (1.0 - p[3]);
            }
        }
        planar
    }

    /// An image filled with one premultiplied colour.
    pub fn filled(width: u32, height: u32, rgba: [f32; 4]) -> Self {
        let mut im = Self::new(width, height);
        for px in im.data.chunks_exact_mut(4) {
            px.copy_from_slice(&rgba);
        }
        im
    }

    pub fn len_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    pub fn pixel(&self, x: u32, y: u32) -> [f32; 4] {
        let i = 4 * (y as usize * self.width as usize + x as usize);
        [
            self.data[i],
            self.data[i + 1],
            self.data[i + 2],
            self.data[i + 3],
        ]
    }

    /// Composites over an opaque colour and returns the RGB result as a new opaque image.
    pub fn over(&self, rgb: [f32; 3]) -> Image {
        let mut out = self.clone();
        for px in out.data.chunks_exact_mut(4) {
            let a = px[3];
            for c in 0..3 {
                px[c] += (1.0 - a) * rgb[c];
            }
            px[3] = 1.0;
        }
        out
    }

    /// Decodes PNG/JPEG bytes (8 or 16 bit) into a premultiplied image.
    pub fn decode(bytes: &[u8]) -> Result<Image, ImageError> {
        let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| ImageError::Decode(e.to_string()))?;
        let (w, h) = reader
            .into_dimensions()
            .map_err(|e| ImageError::Decode(e.to_string()))?;
        if w == 0 || h == 0 {
            return Err(ImageError::Empty);
        }
        if w > MAX_DECODE_SIDE || h > MAX_DECODE_SIDE {
            return Err(ImageError::TooLarge {
                width: w,
                height: h,
                limit: MAX_DECODE_SIDE,
            });
        }
        let dynimg =
            image::load_from_memory(bytes).map_err(|e| ImageError::Decode(e.to_string()))?;
        let rgba = dynimg.to_rgba32f();
        let mut data = rgba.into_raw();
        for px in data.chunks_exact_mut(4) {
            let a = px[3];
            px[0] *= a;
            px[1] *= a;
            px[2] *= a;
        }
        Ok(Image {
            width: w,
            height: h,
            data,
        })
    }

    pub fn open(path: &Path) -> Result<Image, ImageError> {
        let bytes = std::fs::read(path).map_err(|source| ImageError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::decode(&bytes)
    }

    /// 8-bit straight-alpha RGBA bytes (un-premultiplied, rounded).
    pub fn to_rgba8(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.data.len());
        for px in self.data.chunks_exact(4) {
            let a = px[3].clamp(0.0, 1.0);
            let un = |v: f32| {
                if a > 0.0 {
                    (v / a).clamp(0.0, 1.0)
                } else {
                    0.0
                }
            };
            out.push((un(px[0]) * 255.0).round() as u8);
            out.push((un(px[1]) * 255.0).round() as u8);
            out.push((un(px[2]) * 255.0).round() as u8);
            out.push((a * 255.0).round() as u8);
        }
        out
    }

    /// Encodes as an 8-bit RGBA PNG.
    pub fn encode_png(&self) -> Result<Vec<u8>, ImageError> {
        let buf = image::RgbaImage::from_raw(self.width, self.height, self.to_rgba8())
            .ok_or_else(|| ImageError::Encode("buffer size mismatch".into()))?;
        let mut out = Vec::new();
        buf.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png)
            .map_err(|e| ImageError::Encode(e.to_string()))?;
        Ok(out)
    }

    pub fn save_png(&self, path: &Path) -> Result<(), ImageError> {
        let bytes = self.encode_png()?;
        std::fs::write(path, bytes).map_err(|source| ImageError::Io {
            path: path.display().to_string(),
            source,
        })
    }
}

/// The central difference `(f(im + h·eᵢ) − f(im − h·eᵢ)) / 2h` along value `i` of `im`: what
/// the gradient tests compare hand-written VJPs with.
#[cfg(test)]
pub(crate) fn central_difference(im: &Image, i: usize, h: f32, f: impl Fn(&Image) -> f64) -> f64 {
    let (mut p, mut m) = (im.clone(), im.clone());
    p.data[i] += h;
    m.data[i] -= h;
    (f(&p) - f(&m)) / (2.0 * h as f64)
}

/// Mean squared error over RGB channels of two images of the same size, both composited over
/// white first. Panics never: mismatched sizes return `f64::INFINITY`.
pub fn mse_rgb_over_white(a: &Image, b: &Image) -> f64 {
    if a.width != b.width || a.height != b.height || a.data.is_empty() {
        return f64::INFINITY;
    }
    sq_err_rgb_over_white(&a.data, &b.data) / (3.0 * a.len_pixels() as f64)
}

/// The sum behind [`mse_rgb_over_white`] over two runs of premultiplied RGBA pixels, summed in
/// pixel order: pixels equal in both add exactly nothing, so the sum over the rows where two
/// images differ is their whole sum bit for bit.
pub fn sq_err_rgb_over_white(a: &[f32], b: &[f32]) -> f64 {
    let mut s = 0.0f64;
    for (p, q) in a.chunks_exact(4).zip(b.chunks_exact(4)) {
        for c in 0..3 {
            let x = (p[c] + 1.0 - p[3]) as f64;
            let y = (q[c] + 1.0 - q[3]) as f64;
            s += (x - y) * (x - y);
        }
    }
    s
}

/// PSNR in dB (peak 1.0) on RGB composited over white; `f64::INFINITY` for identical images.
pub fn psnr(a: &Image, b: &Image) -> f64 {
    let m = mse_rgb_over_white(a, b);
    if m == 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / m).log10()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_and_psnr() {
        let mut im = Image::filled(5, 3, [0.5, 0.25, 0.0, 1.0]);
        im.data[0] = 1.0;
        let png = im.encode_png().unwrap();
        let back = Image::decode(&png).unwrap();
        assert_eq!((back.width, back.height), (5, 3));
        assert!(psnr(&im, &back) > 40.0);
        assert_eq!(psnr(&im, &im), f64::INFINITY);
        let other = Image::filled(5, 3, [0.0, 0.0, 0.0, 1.0]);
        assert!(psnr(&im, &other) < 10.0);
    }

    #[test]
    fn garbage_is_an_error_not_a_panic() {
        assert!(Image::decode(b"not an image").is_err());
        assert!(Image::decode(&[0x89, b'P', b'N', b'G']).is_err());
    }
}
