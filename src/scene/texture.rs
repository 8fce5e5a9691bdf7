//! Texture paint: a sampled raster (an imported SVG `<image>`) that fills a shape.
//!
//! A [`Texture`] is a grid of premultiplied RGBA8 texels, an affine map from texel space (texel
//! `(i, j)` covers `[i, i+1] × [j, j+1]`) to canvas pixels, how it extends past its edge and how
//! it is sampled. It rides on a shape's [`super::Gradients::texture`] as the shape's fill paint;
//! the flat fill colour stays beside it as its stand-in (the mean texel colour), read by
//! colour-only code and ignored when drawing, exactly as for gradients.
//!
//! The rasteriser samples it at each pixel centre mapped into texel space: bilinearly between
//! the four nearest texel centres in premultiplied RGBA ([`Texture::smooth`]) or the texel under
//! the point (SVG `image-rendering: optimizeSpeed`, `pixelated`, `crisp-edges`). Texels are
//! constants: no parameter, no gradient (see `raster::texture`).
//!
//! # Invariants (checked by [`Texture::validate`], part of [`super::Scene::validate`])
//! - `1 <= width, height <= MAX_SIDE` and `pixels.len() == 4 · width · height`;
//! - every colour byte is at most its alpha byte (premultiplied);
//! - `transform` is finite and invertible;
//! - the shape has a fill and no fill gradient.

use super::{Affine, MAX_SIDE, Rgba};
use serde::{Deserialize, Serialize};

/// What a texture shows outside its texels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureEdge {
    /// The border texels continue (an image: its shape ends at its rectangle).
    #[default]
    Pad,
    /// The texels tile the plane.
    Repeat,
}

/// A sampled raster fill (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    /// Premultiplied RGBA8, row by row; base64 in scene JSON.
    #[serde(with = "b64")]
    pub pixels: Vec<u8>,
    /// Texel space → canvas pixels.
    pub transform: Affine,
    #[serde(default)]
    pub edge: TextureEdge,
    /// Bilinear (true) or nearest-texel sampling.
    pub smooth: bool,
}

impl Texture {
    /// The mean texel colour (straight alpha): the flat stand-in kept beside the texture.
    pub fn mean_color(&self) -> Rgba {
        let mut s = [0f64; 4];
        for px in self.pixels.chunks_exact(4) {
            for (acc, v) in s.iter_mut().zip(px) {
                *acc += f64::from(*v);
            }
        }
        if s[3] <= 0.0 {
            return Rgba::TRANSPARENT;
        }
        let n = (self.pixels.len() / 4).max(1) as f64;
        let c = |v: f64| (v / s[3]) as f32;
        Rgba::new(c(s[0]), c(s[1]), c(s[2]), (s[3] / n / 255.0) as f32).clamped()
    }

    /// The texture moved with its shape: `m` (canvas → new canvas) after its transform.
    pub fn mapped(&self, m: &Affine) -> Texture {
        Texture {
            transform: m.then_after(&self.transform),
            ..self.clone()
        }
    }

    /// Checks the invariants in the module docs (the shape's part is checked by the shape).
    pub fn validate(&self) -> Result<(), String> {
        let (w, h) = (self.width, self.height);
        if !(1..=MAX_SIDE).contains(&w) || !(1..=MAX_SIDE).contains(&h) {
            return Err(format!("texture size {w}x{h} is out of range"));
        }
        if self.pixels.len() != 4 * w as usize * h as usize {
            return Err(format!(
                "texture has {} bytes, expected {}",
                self.pixels.len(),
                4 * w as usize * h as usize
            ));
        }
        if self
            .pixels
            .chunks_exact(4)
            .any(|p| p[0] > p[3] || p[1] > p[3] || p[2] > p[3])
        {
            return Err("texture pixels must be premultiplied".into());
        }
        if !self.transform.is_valid() {
            return Err("texture transform must be finite and invertible".into());
        }
        Ok(())
    }
}

/// The texture part of a shape's paint check: a fill, no fill gradient, a valid texture.
pub(crate) fn validate_on(g: &super::Gradients, has_fill: bool) -> Result<(), String> {
    let Some(t) = &g.texture else {
        return Ok(());
    };
    if !has_fill || g.fill.is_some() {
        return Err("a texture needs a fill without a fill gradient".into());
    }
    t.validate().map_err(|e| format!("fill {e}"))
}

/// Texels as a base64 string in serialised scenes.
mod b64 {
    use base64::Engine;
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&base64::engine::general_purpose::STANDARD.encode(v))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        let text = String::deserialize(d)?;
        base64::engine::general_purpose::STANDARD
            .decode(text.as_bytes())
            .map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tex(pixels: Vec<u8>) -> Texture {
        Texture {
            width: 2,
            height: 1,
            pixels,
            transform: Affine::IDENTITY,
            edge: TextureEdge::Pad,
            smooth: true,
        }
    }

    #[test]
    fn validates_size_premultiplication_and_transform() {
        assert_eq!(tex(vec![255, 0, 0, 255, 0, 0, 0, 0]).validate(), Ok(()));
        assert!(tex(vec![0; 4]).validate().is_err());
        assert!(tex(vec![200, 0, 0, 100, 0, 0, 0, 0]).validate().is_err());
        let mut t = tex(vec![0; 8]);
        t.transform = Affine([0.0; 6]);
        assert!(t.validate().is_err());
    }

    #[test]
    fn mean_colour_and_json_round_trip() {
        let t = tex(vec![255, 0, 0, 255, 0, 0, 0, 0]);
        let m = t.mean_color();
        assert_eq!((m.r, m.g, m.a), (1.0, 0.0, 0.5));
        let json = serde_json::to_string(&t).unwrap();
        assert!(json.contains("\"pixels\":\"/wAA/wAAAAA=\""), "{json}");
        let back: Texture = serde_json::from_str(&json).unwrap();
        assert_eq!(back, t);
    }
}
