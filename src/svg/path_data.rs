//! Path data (`d`) of the SVG writer: integer coordinates in units of `10^-precision`, each
//! command written in its shortest exact form (relative or absolute, `H`/`V`, `S`, `Z`), with
//! the fewest separators the grammar allows.

use super::export::{num, push_fixed, to_units};
use crate::scene::{Point, Shape, ShapeKind};

/// Where the previous token of path data ended, for the separator rules.
#[derive(Clone, Copy, Debug)]
struct Pen {
    /// The last command letter written (`0` before the first).
    cmd: u8,
    /// `Some(has_point)` when the last token was a number.
    last_num: Option<bool>,
}

impl Pen {
    /// The command a bare number list continues with after `cmd`.
    fn implicit(self) -> u8 {
        match self.cmd {
            b'M' => b'L',
            b'm' => b'l',
            c => c,
        }
    }
}

/// Appends command `letter` with `nums` (units of `10^-p`) to `out`: the letter only if the
/// grammar would not repeat it anyway, a space only where the next number would otherwise run
/// into the previous one.
fn push_cmd(out: &mut String, pen: &mut Pen, letter: u8, nums: &[i64], p: usize) {
    if pen.cmd == 0 || letter != pen.implicit() {
        out.push(letter as char);
        pen.cmd = letter;
        pen.last_num = None;
    }
    let mut tok = String::new();
    for &n in nums {
        tok.clear();
        push_fixed(&mut tok, n, p);
        if let Some(had_point) = pen.last_num {
            let glued = tok.starts_with('-') || (tok.starts_with('.') && had_point);
            if !glued {
                out.push(' ');
            }
        }
        out.push_str(&tok);
        pen.last_num = Some(tok.contains('.'));
    }
}

/// Appends the shortest of `candidates` (letter, numbers); the first wins ties.
fn push_best(out: &mut String, pen: &mut Pen, p: usize, candidates: &[(u8, Vec<i64>)]) {
    let mut best: Option<(String, Pen)> = None;
    for (letter, nums) in candidates {
        let mut s = String::new();
        let mut q = *pen;
        push_cmd(&mut s, &mut q, *letter, nums, p);
        if best.as_ref().is_none_or(|(b, _)| s.len() < b.len()) {
            best = Some((s, q));
        }
    }
    if let Some((s, q)) = best {
        out.push_str(&s);
        *pen = q;
    }
}

type U2 = [i64; 2];

/// The current point and the previous segment's second control point (after `C`/`S` only),
/// in rounded units: exactly what a reader of the text has.
struct Cursor {
    pen: Pen,
    cur: U2,
    prev_c2: Option<U2>,
}

fn rel(a: U2, from: U2) -> U2 {
    [a[0] - from[0], a[1] - from[1]]
}

impl Cursor {
    fn line(&mut self, out: &mut String, e: U2, p: usize) {
        let (c, d) = (self.cur, rel(e, self.cur));
        let mut cands = Vec::with_capacity(4);
        if e[1] == c[1] {
            cands.push((b'H', vec![e[0]]));
            cands.push((b'h', vec![d[0]]));
        }
        if e[0] == c[0] {
            cands.push((b'V', vec![e[1]]));
            cands.push((b'v', vec![d[1]]));
        }
        cands.push((b'L', e.to_vec()));
        cands.push((b'l', d.to_vec()));
        push_best(out, &mut self.pen, p, &cands);
        self.cur = e;
        self.prev_c2 = None;
    }

    fn cubic(&mut self, out: &mut String, c1: U2, c2: U2, e: U2, p: usize) {
        let c = self.cur;
        let reflected = match self.prev_c2 {
            Some(q) => [2 * c[0] - q[0], 2 * c[1] - q[1]],
            None => c,
        };
        let mut cands = Vec::with_capacity(4);
        if c1 == reflected {
            cands.push((b'S', [c2, e].concat()));
            cands.push((b's', [rel(c2, c), rel(e, c)].concat()));
        }
        cands.push((b'C', [c1, c2, e].concat()));
        cands.push((b'c', [rel(c1, c), rel(c2, c), rel(e, c)].concat()));
        push_best(out, &mut self.pen, p, &cands);
        self.cur = e;
        self.prev_c2 = Some(c2);
    }
}

/// Whether the cubic `seg` (original coordinates) is, within half a unit, the straight segment
/// a reader builds for `L` from the rounded ends `a`, `b`: its control points on the chord
/// between the ends (spaced anyhow: such a cubic traces the chord and nothing else).
fn is_straight(seg: &[Point; 4], a: U2, b: U2, scale: f64) -> bool {
    let at = |c: Point| [c.x as f64 * scale, c.y as f64 * scale];
    let end = |u: U2| [u[0] as f64, u[1] as f64];
    crate::vector::straight::collinear_inside(end(a), at(seg[1]), at(seg[2]), end(b), 0.5)
}

pub(super) fn push_path_data(out: &mut String, sh: &Shape, p: usize) {
    let scale = 10f64.powi(p as i32);
    let n = sh.num_segments();
    let segs: Vec<[Point; 4]> = (0..n).map(|i| sh.segment(i)).collect();
    let rounded: Option<Vec<[U2; 4]>> = segs
        .iter()
        .map(|s| {
            let mut r = [[0i64; 2]; 4];
            for (k, pt) in s.iter().enumerate() {
                r[k] = [to_units(pt.x, scale)?, to_units(pt.y, scale)?];
            }
            Some(r)
        })
        .collect();
    let Some(rounded) = rounded.filter(|r| !r.is_empty()) else {
        push_path_data_plain(out, sh, p);
        return;
    };
    let straight = |i: usize| {
        sh.kind == ShapeKind::Polygon || is_straight(&segs[i], rounded[i][0], rounded[i][3], scale)
    };
    let mut cur = Cursor {
        pen: Pen {
            cmd: 0,
            last_num: None,
        },
        cur: rounded[0][0],
        prev_c2: None,
    };
    push_cmd(out, &mut cur.pen, b'M', &rounded[0][0], p);
    let closed = sh.is_closed();
    // A closed outline's last segment is left to `Z` when it is a straight line of non-zero
    // length (`Z` draws nothing for a zero-length one, and a reader would drop the segment).
    let implicit_close = closed && straight(n - 1) && rounded[n - 1][0] != rounded[0][0];
    let explicit = if implicit_close { n - 1 } else { n };
    for (i, r) in rounded.iter().enumerate().take(explicit) {
        if straight(i) {
            cur.line(out, r[3], p);
        } else {
            cur.cubic(out, r[1], r[2], r[3], p);
        }
    }
    if closed {
        out.push('Z');
    }
}

/// The plain absolute form, for shapes with values the integer path cannot hold.
fn push_path_data_plain(out: &mut String, sh: &Shape, p: usize) {
    let pt = |out: &mut String, q: Point| {
        out.push_str(&num(q.x, p));
        out.push(' ');
        out.push_str(&num(q.y, p));
    };
    let Some(first) = sh.points.first() else {
        return;
    };
    out.push('M');
    pt(out, *first);
    for i in 0..sh.num_segments() {
        let s = sh.segment(i);
        out.push('C');
        for (k, q) in s[1..].iter().enumerate() {
            if k > 0 {
                out.push(' ');
            }
            pt(out, *q);
        }
    }
    if sh.is_closed() {
        out.push('Z');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn separators_only_where_needed() {
        let mut s = String::new();
        let mut pen = Pen {
            cmd: 0,
            last_num: None,
        };
        push_cmd(&mut s, &mut pen, b'M', &[10, 20], 1);
        push_cmd(&mut s, &mut pen, b'L', &[5, -5], 1);
        push_cmd(&mut s, &mut pen, b'l', &[-5, 5], 1);
        push_cmd(&mut s, &mut pen, b'l', &[15, 5], 1);
        push_cmd(&mut s, &mut pen, b'h', &[5], 1);
        assert_eq!(s, "M1 2 .5-.5l-.5.5 1.5.5h.5");
    }
}
