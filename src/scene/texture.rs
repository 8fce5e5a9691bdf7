//! Texture paint: a sampled raster (an imported SVG `<image>`) that fills a shape.
//!
//! A [`Texture`] is a grid of premultiplied RGBA8 texels, an affine map from texel space (texel
//! `(i, j)` covers `[i, i+1] × [j, j+1]`) to canvas pixels, how it extends past its edge and how
//! it is sampled. It rides on a shape's [`super::Gradients::texture`] as the shape's fill paint;
//! the flat fill colour stays beside it as its stand-in (the mean texel colour), read by
//! colour-only code and ignored when drawing, exactly as for gradients.
//!
//! The rasteriser samples it at each pixel centre mapped into texel space, by its
//! [`TextureFilter`]: the texel under the point (SVG `image-rendering: optimizeSpeed`,
//! `pixelated`, `crisp-edges`), bilinearly between the four nearest texel centres (`smooth`), or
//! with the bicubic Mitchell–Netravali filter (B = C = 1/3) over the sixteen nearest (the default
//! `optimizeQuality`, and patterns), in premultiplied RGBA. Texels are constants: no parameter,
//! no gradient (see `raster::texture`).
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

/// How a texture is sampled between its texels (SVG `image-rendering`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureFilter {
    /// The texel under the point (`optimizeSpeed`, `pixelated`, `crisp-edges`).
    Nearest,
    /// Bilinear between the four nearest texel centres (`smooth`).
    Bilinear,
    /// Mitchell–Netravali bicubic (B = C = 1/3) over the sixteen nearest texel centres, clamped
    /// to [0, 1] (`optimizeQuality`, `high-quality`, and pattern tiles).
    #[default]
    Bicubic,
}

/// A sampled raster fill (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "TextureWire")]
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
    pub filter: TextureFilter,
}

/// A serialised texture, as written now (`filter`) or before filters had names (`smooth`: true
/// was bilinear, false nearest), so a stored scene draws as it did.
#[derive(Deserialize)]
struct TextureWire {
    width: u32,
    height: u32,
    #[serde(with = "b64")]
    pixels: Vec<u8>,
    transform: Affine,
    #[serde(default)]
    edge: TextureEdge,
    #[serde(default)]
    filter: Option<TextureFilter>,
    #[serde(default)]
    smooth: Option<bool>,
}

impl From<TextureWire> for Texture {
    fn from(w: TextureWire) -> Self {
        let legacy = w.smooth.map(|s| {
            if s {
                TextureFilter::Bilinear
            } else {
                TextureFilter::Nearest
            }
        });
        Texture {
            width: w.width,
            height: w.height,
            pixels: w.pixels,
            transform: w.transform,
            edge: w.edge,
            filter: w.filter.or(legacy).unwrap_or_default(),
        }
    }
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

    /// The texels with straight alpha (RGBA8, each colour divided by its alpha, rounded), as
    /// image files store them.
    pub fn straight_pixels(&self) -> Vec<u8> {
        let mut straight = self.pixels.clone();
        for p in straight.chunks_exact_mut(4) {
            let a = u16::from(p[3]);
            for c in &mut p[..3] {
                if let Some(v) = (u16::from(*c) * 255 + a / 2).checked_div(a) {
                    *c = v.min(255) as u8;
                }
            }
        }
        straight
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
            filter: TextureFilter::Bicubic,
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
        assert!(json.contains("\"filter\":\"bicubic\""), "{json}");
        let back: Texture = serde_json::from_str(&json).unwrap();
        assert_eq!(back, t);
    }

    #[test]
    fn a_scene_stored_before_filters_had_names_samples_as_it_did() {
        let t = tex(vec![255, 0, 0, 255, 0, 0, 0, 0]);
        let json = serde_json::to_string(&t).unwrap();
        for (smooth, filter) in [
            ("true", TextureFilter::Bilinear),
            ("false", TextureFilter::Nearest),
        ] {
            let old = json.replace("\"filter\":\"bicubic\"", &format!("\"smooth\":{smooth}"));
            assert!(!old.contains("filter"), "{old}");
            let back: Texture = serde_json::from_str(&old).unwrap();
            assert_eq!(back.filter, filter);
        }
    }
}
