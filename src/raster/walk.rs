//! Exact area coverage: walking a line segment through the pixel grid.
//!
//! The forward pass deposits, for every piece of an edge inside one pixel cell, the signed
//! area between the piece and the cell's right border into an accumulation row (plus the rest
//! of the piece's height into the next cell). A prefix sum along the row then gives, for every
//! pixel, the exact integral of the winding number over the pixel square (box-filtered
//! coverage). The backward pass is the exact derivative of that integral (Reynolds transport):
//! moving an edge point by `v` changes the integral over a cell by
//! `-(v.x * d.y - v.y * d.x)` per unit of edge parameter inside the cell (`d = p1 - p0`).

use super::real::Real;

/// A clip rectangle in pixel units, `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Clip {
    pub x0: i32,
    pub x1: i32,
    pub y0: i32,
    pub y1: i32,
}

/// Column value passed for pieces left of the clip (they cover the whole row).
pub(crate) const LEFT: i32 = i32::MIN;

/// Ascending parameters in `(sa, sb)` where `p + s * d` crosses an integer in `[lo, hi]`.
#[inline]
fn crossings<T: Real>(p: T, d: T, sa: T, sb: T, lo: i32, hi: i32) -> Crossings<T> {
    if d == T::zero() {
        return Crossings::empty();
    }
    let va = p + sa * d;
    let vb = p + sb * d;
    let (vlo, vhi) = if va < vb { (va, vb) } else { (vb, va) };
    // Integers strictly inside (vlo, vhi), limited to [lo, hi].
    let k0 = (vlo.floor_i32() as i64 + 1).max(lo as i64);
    let k1 = (-((-vhi).floor_i32() as i64) - 1).min(hi as i64);
    if k1 < k0 {
        return Crossings::empty();
    }
    let inv = d.recip();
    let (start, step) = if d > T::zero() { (k0, 1) } else { (k1, -1) };
    Crossings {
        p,
        inv,
        sa,
        sb,
        k: start,
        step,
        left: (k1 - k0 + 1) as u64,
    }
}

struct Crossings<T> {
    p: T,
    inv: T,
    sa: T,
    sb: T,
    k: i64,
    step: i64,
    left: u64,
}

impl<T: Real> Crossings<T> {
    fn empty() -> Self {
        Crossings {
            p: T::zero(),
            inv: T::zero(),
            sa: T::zero(),
            sb: T::zero(),
            k: 0,
            step: 0,
            left: 0,
        }
    }

    #[inline]
    fn peek(&self) -> Option<T> {
        if self.left == 0 {
            return None;
        }
        let s = (T::c(self.k as f64) - self.p) * self.inv;
        Some(s.max(self.sa).min(self.sb))
    }

    #[inline]
    fn advance(&mut self) {
        self.left -= 1;
        self.k += self.step;
    }
}

/// Calls `f(col, row, a, b, sa, sb)` for every piece of segment `p0 → p1` inside the clip
/// rows, split at integer x and y. Pieces left of the clip get `col == LEFT` (split at rows
/// only); pieces right of it are skipped. `sa, sb` are the piece's parameter range.
#[inline]
pub(crate) fn walk<T: Real>(
    p0: [T; 2],
    p1: [T; 2],
    clip: Clip,
    mut f: impl FnMut(i32, i32, [T; 2], [T; 2], T, T),
) {
    let d = [p1[0] - p0[0], p1[1] - p0[1]];
    let (y0, y1) = (T::c(clip.y0 as f64), T::c(clip.y1 as f64));
    let (x0, x1) = (T::c(clip.x0 as f64), T::c(clip.x1 as f64));
    let (mut s_lo, mut s_hi) = (T::zero(), T::one());
    if d[1] == T::zero() {
        if !(p0[1] >= y0 && p0[1] < y1) {
            return;
        }
    } else {
        let (a, b) = slab(p0[1], d[1], y0, y1);
        s_lo = s_lo.max(a);
        s_hi = s_hi.min(b);
    }
    if !(s_lo < s_hi) {
        return;
    }
    // Split the y-range into left / middle / right by x.
    let (mut m_lo, mut m_hi) = (s_lo, s_hi);
    if d[0] == T::zero() {
        if p0[0] >= x1 {
            return;
        }
        if p0[0] < x0 {
            pieces(p0, d, s_lo, s_hi, clip, false, LEFT, &mut f);
            return;
        }
    } else {
        let (a, b) = slab(p0[0], d[0], x0, x1);
        m_lo = m_lo.max(a);
        m_hi = m_hi.min(b);
        // Left part: where x < x0.
        let (l_lo, l_hi) = if d[0] > T::zero() {
            (s_lo, s_hi.min(a))
        } else {
            (s_lo.max(b), s_hi)
        };
        if l_lo < l_hi {
            pieces(p0, d, l_lo, l_hi, clip, false, LEFT, &mut f);
        }
    }
    if m_lo < m_hi {
        pieces(p0, d, m_lo, m_hi, clip, true, 0, &mut f);
    }
}

/// The parameters `a ≤ b` at which `p + s·d` (`d ≠ 0`) crosses `lo` and `hi`: the segment is
/// inside the slab `[lo, hi)` for `s` in between.
#[inline]
fn slab<T: Real>(p: T, d: T, lo: T, hi: T) -> (T, T) {
    let inv = d.recip();
    let a = (lo - p) * inv;
    let b = (hi - p) * inv;
    if a < b { (a, b) } else { (b, a) }
}

#[allow(clippy::too_many_arguments)]
#[inline]
fn pieces<T: Real>(
    p0: [T; 2],
    d: [T; 2],
    sa: T,
    sb: T,
    clip: Clip,
    split_x: bool,
    col_override: i32,
    f: &mut impl FnMut(i32, i32, [T; 2], [T; 2], T, T),
) {
    let mut ys = crossings(p0[1], d[1], sa, sb, clip.y0, clip.y1);
    let mut xs = if split_x {
        crossings(p0[0], d[0], sa, sb, clip.x0, clip.x1)
    } else {
        Crossings::empty()
    };
    let half = T::c(0.5);
    let at = |s: T| [p0[0] + s * d[0], p0[1] + s * d[1]];
    let mut s_prev = sa;
    let mut a = at(sa);
    loop {
        let s_next = match (xs.peek(), ys.peek()) {
            (Some(x), Some(y)) => {
                if x < y {
                    xs.advance();
                    x
                } else {
                    ys.advance();
                    y
                }
            }
            (Some(x), None) => {
                xs.advance();
                x
            }
            (None, Some(y)) => {
                ys.advance();
                y
            }
            (None, None) => sb,
        };
        let b = if s_next == sb { at(sb) } else { at(s_next) };
        if s_next > s_prev {
            let my = (a[1] + b[1]) * half;
            let row = my.floor_i32().clamp(clip.y0, clip.y1 - 1);
            let col = if split_x {
                let mx = (a[0] + b[0]) * half;
                mx.floor_i32().clamp(clip.x0, clip.x1 - 1)
            } else {
                col_override
            };
            f(col, row, a, b, s_prev, s_next);
        }
        if s_next >= sb {
            break;
        }
        s_prev = s_next;
        a = b;
    }
}

/// Forward: deposits edge `p0 → p1` into `acc` (rows `clip.y0..clip.y1`, `stride` =
/// `clip.x1 - clip.x0 + 1` cells per row).
#[inline]
pub(crate) fn deposit<T: Real>(p0: [T; 2], p1: [T; 2], clip: Clip, acc: &mut [T], stride: usize) {
    if p0[1] == p1[1] {
        return;
    }
    walk(p0, p1, clip, |col, row, a, b, _, _| {
        let r = (row - clip.y0) as usize * stride;
        add_piece(acc, r, col, clip, a, b);
    });
}

/// Adds the piece `a → b` in cell `col` (or [`LEFT`]) of the accumulation row starting at
/// `acc[r]`.
#[inline(always)]
fn add_piece<T: Real>(acc: &mut [T], r: usize, col: i32, clip: Clip, a: [T; 2], b: [T; 2]) {
    let dy = b[1] - a[1];
    if col == LEFT {
        acc[r] += dy;
    } else {
        let c = (col - clip.x0) as usize;
        let fx = ((a[0] + b[0]) * T::c(0.5) - T::c(col as f64))
            .max(T::zero())
            .min(T::one());
        acc[r + c] += dy * (T::one() - fx);
        acc[r + c + 1] += dy * fx;
    }
}

/// One piece of an edge inside the clip, recorded by [`deposit_record`] for the backward pass:
/// its cell `(row - y0) * width + (col - x0)` and the weights of dL/dA there for the edge's two
/// end points (the integrals of `1 - s` and `s` over the piece's parameter range).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Piece<T> {
    pub at: u32,
    pub i0: T,
    pub i1: T,
}

/// The weights of [`Piece`] for the parameter range `sa..sb`.
#[inline(always)]
fn piece_weights<T: Real>(sa: T, sb: T) -> (T, T) {
    let i1 = T::c(0.5) * (sb * sb - sa * sa);
    ((sb - sa) - i1, i1)
}

/// [`deposit`], also appending to `rec` every piece inside the clip (left of it is skipped, as
/// in [`edge_grad`]) in walking order: [`edge_grad_recorded`] over them gives what
/// [`edge_grad`] gives, bit for bit, without walking the edge again. Horizontal edges deposit
/// nothing but their pieces are recorded.
#[inline]
pub(crate) fn deposit_record<T: Real>(
    p0: [T; 2],
    p1: [T; 2],
    clip: Clip,
    acc: &mut [T],
    rec: &mut Vec<Piece<T>>,
) {
    let stride = (clip.x1 - clip.x0) as usize + 1;
    let width = stride - 1;
    let flat = p0[1] == p1[1];
    walk(p0, p1, clip, |col, row, a, b, sa, sb| {
        let r = (row - clip.y0) as usize;
        if !flat {
            add_piece(acc, r * stride, col, clip, a, b);
        }
        if col == LEFT {
            return;
        }
        let c = (col - clip.x0) as usize;
        let (i0, i1) = piece_weights(sa, sb);
        let at = (r * width + c) as u32;
        rec.push(Piece { at, i0, i1 });
    });
}

/// [`edge_grad`] from the pieces [`deposit_record`] recorded for edge `p0 → p1`.
#[inline]
pub(crate) fn edge_grad_recorded<T: Real>(
    p0: [T; 2],
    p1: [T; 2],
    pieces: &[Piece<T>],
    g: &[T],
    dp0: &mut [T; 2],
    dp1: &mut [T; 2],
) {
    let n = [p1[1] - p0[1], p0[0] - p1[0]];
    let (mut w0, mut w1) = (T::zero(), T::zero());
    for pc in pieces {
        let gv = g[pc.at as usize];
        if gv == T::zero() {
            continue;
        }
        w0 += gv * pc.i0;
        w1 += gv * pc.i1;
    }
    dp0[0] -= w0 * n[0];
    dp0[1] -= w0 * n[1];
    dp1[0] -= w1 * n[0];
    dp1[1] -= w1 * n[1];
}

/// Backward: given `g[(row - y0) * width + (col - x0)] = dL/dA` over the clip, adds dL/dp0 and
/// dL/dp1 of edge `p0 → p1` (walking the edge; the passes use [`edge_grad_recorded`], the
/// tests check the two agree bit for bit).
#[cfg(test)]
pub(crate) fn edge_grad<T: Real>(
    p0: [T; 2],
    p1: [T; 2],
    clip: Clip,
    g: &[T],
    width: usize,
    dp0: &mut [T; 2],
    dp1: &mut [T; 2],
) {
    let n = [p1[1] - p0[1], p0[0] - p1[0]];
    let (mut w0, mut w1) = (T::zero(), T::zero());
    walk(p0, p1, clip, |col, row, _, _, sa, sb| {
        if col == LEFT {
            return;
        }
        let gv = g[(row - clip.y0) as usize * width + (col - clip.x0) as usize];
        if gv == T::zero() {
            return;
        }
        let (i0, i1) = piece_weights(sa, sb);
        w0 += gv * i0;
        w1 += gv * i1;
    });
    dp0[0] -= w0 * n[0];
    dp0[1] -= w0 * n[1];
    dp1[0] -= w1 * n[0];
    dp1[1] -= w1 * n[1];
}
