//! Texture fills ([`crate::scene::texture`]): the colour of a pixel is the texture sampled at the
//! pixel centre mapped into texel space (bilinear in premultiplied RGBA, or nearest texel; a
//! texture drawn 1:1, moved but not scaled, always nearest),
//! handed to the compositing as straight RGBA like every other [`Shade`].
//!
//! Gradients do not flow into texels (imported image pixels are constants, not parameters): the
//! backward of a texture layer only carries the coverage part, so the shape's outline and the
//! shapes above and below it get their gradients as usual.

use super::paint::{Shade, inverse};
use super::real::Real;
use crate::scene::{Texture, TextureEdge};

/// A texture in the working precision: canvas → texel space, and the texels.
#[derive(Clone, Debug)]
pub(crate) struct TextureT<T> {
    inv: [T; 6],
    width: i32,
    height: i32,
    /// Premultiplied RGBA8 (4 bytes a texel: a large image stays small).
    texels: Vec<[u8; 4]>,
    edge: TextureEdge,
    smooth: bool,
}

impl<T: Real> TextureT<T> {
    pub fn of(t: &Texture) -> Self {
        TextureT {
            inv: inverse(&t.transform),
            width: t.width as i32,
            height: t.height as i32,
            texels: t
                .pixels
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
            edge: t.edge,
            smooth: t.smooth && !is_translation(&t.transform),
        }
    }

    /// Texel `(i, j)` after the edge mode.
    #[inline]
    fn texel(&self, i: i32, j: i32) -> [T; 4] {
        let (i, j) = match self.edge {
            TextureEdge::Pad => (i.clamp(0, self.width - 1), j.clamp(0, self.height - 1)),
            TextureEdge::Repeat => (i.rem_euclid(self.width), j.rem_euclid(self.height)),
        };
        let k = T::c(1.0 / 255.0);
        self.texels[(j * self.width + i) as usize].map(|v| T::c(f64::from(v)) * k)
    }

    /// Premultiplied colour at canvas pixel `(x, y)`'s centre.
    fn sample(&self, x: i32, y: i32) -> [T; 4] {
        let h = T::c(0.5);
        let (px, py) = (T::c(x as f64) + h, T::c(y as f64) + h);
        let m = &self.inv;
        let u = m[0] * px + m[2] * py + m[4];
        let v = m[1] * px + m[3] * py + m[5];
        if !(u.is_finite() && v.is_finite()) {
            return [T::zero(); 4];
        }
        // Far outside the texture the edge mode decides alone; keep the index in i32 range.
        let lim = T::c(1e6);
        let (u, v) = (u.max(-lim).min(lim), v.max(-lim).min(lim));
        if !self.smooth {
            return self.texel(u.floor().as_f32() as i32, v.floor().as_f32() as i32);
        }
        let (u, v) = (u - h, v - h);
        let (fu, fv) = (u.floor(), v.floor());
        let (i, j) = (fu.as_f32() as i32, fv.as_f32() as i32);
        let (wx, wy) = (u - fu, v - fv);
        let (a, b) = (self.texel(i, j), self.texel(i + 1, j));
        let (c, d) = (self.texel(i, j + 1), self.texel(i + 1, j + 1));
        let one = T::one();
        std::array::from_fn(|k| {
            let top = a[k] * (one - wx) + b[k] * wx;
            let bottom = c[k] * (one - wx) + d[k] * wx;
            top * (one - wy) + bottom * wy
        })
    }
}

/// Whether `m` only moves texels (exactly: no scale, rotation or skew): a texture drawn 1:1 is
/// not resampled, so a tile placed at a half pixel stays crisp instead of blurring every edge
/// into a half-tone line (tiny-skia makes the same choice, by the same exact test).
#[allow(clippy::float_cmp)]
fn is_translation(m: &crate::scene::Affine) -> bool {
    let [a, b, c, d, _, _] = m.0;
    a == 1.0 && d == 1.0 && b == 0.0 && c == 0.0
}

/// A texture layer's shader (no parameters: its backward is empty).
pub(crate) struct TextureShade<'a, T>(pub &'a TextureT<T>);

impl<T: Real> Shade<T> for TextureShade<'_, T> {
    fn color(&self, x: i32, y: i32) -> [T; 4] {
        let p = self.0.sample(x, y);
        let a = p[3];
        if !(a > T::c(1e-9)) {
            return [T::zero(); 4];
        }
        [
            (p[0] / a).min(T::one()),
            (p[1] / a).min(T::one()),
            (p[2] / a).min(T::one()),
            a.min(T::one()),
        ]
    }

    fn grad(&mut self, _: i32, _: i32, _: [T; 4]) {}
}
