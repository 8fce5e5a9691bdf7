//! Texture fills ([`crate::scene::texture`]): the colour of a pixel is the texture sampled at the
//! pixel centre mapped into texel space by the texture's [`TextureFilter`] (nearest texel,
//! bilinear, or Mitchell–Netravali bicubic, in premultiplied RGBA; a texture drawn 1:1, moved
//! but not scaled, always nearest),
//! handed to the compositing as straight RGBA like every other [`Shade`].
//!
//! Gradients do not flow into texels (imported image pixels are constants, not parameters): the
//! backward of a texture layer only carries the coverage part, so the shape's outline and the
//! shapes above and below it get their gradients as usual.

use super::paint::Shade;
use super::real::Real;
use crate::scene::{Texture, TextureEdge, TextureFilter};

/// A texture in the working precision: canvas → texel space, and the texels.
#[derive(Clone, Debug)]
pub(crate) struct TextureT<T> {
    inv: [T; 6],
    width: i32,
    height: i32,
    /// Premultiplied RGBA8 (4 bytes a texel: a large image stays small).
    texels: Vec<[u8; 4]>,
    edge: TextureEdge,
    filter: TextureFilter,
}

impl<T: Real> TextureT<T> {
    pub fn of(t: &Texture) -> Self {
        TextureT {
            inv: t.transform.inverse_f64().map(T::c),
            width: t.width as i32,
            height: t.height as i32,
            texels: t
                .pixels
                .chunks_exact(4)
                .map(|p| [p[0], p[1], p[2], p[3]])
                .collect(),
            edge: t.edge,
            filter: if is_translation(&t.transform) {
                TextureFilter::Nearest
            } else {
                t.filter
            },
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
        let (fu, fv) = match self.filter {
            TextureFilter::Nearest => {
                return self.texel(u.floor().as_f32() as i32, v.floor().as_f32() as i32);
            }
            TextureFilter::Bilinear | TextureFilter::Bicubic => (u - h, v - h),
        };
        // Texel centres sit at i + 1/2: `(i, j)` is the centre at or before the point, `(wx, wy)`
        // how far past it the point lies.
        let (iu, iv) = (fu.floor(), fv.floor());
        let (i, j) = (iu.as_f32() as i32, iv.as_f32() as i32);
        let (wx, wy) = (fu - iu, fv - iv);
        if self.filter == TextureFilter::Bilinear {
            let (a, b) = (self.texel(i, j), self.texel(i + 1, j));
            let (c, d) = (self.texel(i, j + 1), self.texel(i + 1, j + 1));
            let one = T::one();
            return std::array::from_fn(|k| {
                let top = a[k] * (one - wx) + b[k] * wx;
                let bottom = c[k] * (one - wx) + d[k] * wx;
                top * (one - wy) + bottom * wy
            });
        }
        // Bicubic: the centres at i − 1 … i + 2 lie 1 + w, w, 1 − w, 2 − w from the point.
        let one = T::one();
        let two = T::c(2.0);
        let kx = [one + wx, wx, one - wx, two - wx].map(mitchell);
        let ky = [one + wy, wy, one - wy, two - wy].map(mitchell);
        let mut acc = [T::zero(); 4];
        for (dj, &wj) in ky.iter().enumerate() {
            for (di, &wi) in kx.iter().enumerate() {
                let t = self.texel(i - 1 + di as i32, j - 1 + dj as i32);
                let w = wi * wj;
                for k in 0..4 {
                    acc[k] += t[k] * w;
                }
            }
        }
        // The filter's negative lobes can overshoot: clamp as a colour.
        acc.map(|c| c.max(T::zero()).min(one))
    }
}

/// The Mitchell–Netravali cubic with B = C = 1/3 at distance `d` ≥ 0 (zero from 2 on): weights at
/// distances 1 + w, w, 1 − w, 2 − w sum to one for every w in [0, 1).
fn mitchell<T: Real>(d: T) -> T {
    let c = |v: f64| T::c(v);
    if d < T::one() {
        ((c(7.0 / 6.0) * d - c(2.0)) * d) * d + c(8.0 / 9.0)
    } else if d < c(2.0) {
        ((c(-7.0 / 18.0) * d + c(2.0)) * d - c(10.0 / 3.0)) * d + c(16.0 / 9.0)
    } else {
        T::zero()
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
