#!/usr/bin/env python3
"""Outside measure of self-intersecting paths in SVGs (shapely), to cross-check
`vectorfusion::vector::check`.

For every SVG in a folder, every shape element (path, rect, circle, ...) with a fill or a
stroke is a path; the first one is the background (not counted) when its fill covers at
least 99.5 % of the canvas, as in the Rust check. A filled path is self-intersecting when
  - some subpath, flattened finely to a ring, is not a valid polygon: `Polygon(ring).is_valid`
    is false (crossing, touching itself, a 180-degree fold, no area) or the ring has fewer
    than 3 distinct points; or
  - two rings of the path meet in more than a single point (a hole may touch its shell once).

Curves are flattened adaptively: split until the control points lie within 4/3 * step of the
chord (so the curve within `step` px, default 0.01, the Rust check's tolerance); `--uniform`
samples each curve uniformly in t about `step` px apart instead, which also sees loops far
smaller than the tolerance (e.g. ones made by rounding handles to 2 decimals).

Prints one JSON object per file, {"file", "paths", "self_intersecting"}, then the totals.

Setup (a throwaway venv, never committed):
    python3 -m venv /tmp/svgenv && /tmp/svgenv/bin/pip install shapely svgelements
    /tmp/svgenv/bin/python scripts/svg_editability.py FOLDER [--step 0.01] [--uniform] [--details]
"""

import argparse
import json
import math
import sys
from pathlib import Path as FsPath

from shapely.geometry import LinearRing, Polygon, box
from shapely.validation import make_valid
from shapely.validation import explain_validity
import svgelements as se


def _cubic_flat(p0, p1, p2, p3, tol, out, depth=0):
    """Adaptive subdivision until the handles lie within `tol` of the chord (the same
    flattening-error meaning as kurbo's tolerance in the Rust check)."""
    (x0, y0), (x3, y3) = p0, p3
    dx, dy = x3 - x0, y3 - y0
    d = math.hypot(dx, dy)

    def off(p):
        if d == 0.0:
            return math.hypot(p[0] - x0, p[1] - y0)
        return abs((p[0] - x0) * dy - (p[1] - y0) * dx) / d

    # The curve lies within 3/4 of the handles' distance from the chord.
    if depth >= 24 or 0.75 * max(off(p1), off(p2)) <= tol:
        out.append(p3)
        return
    mid = lambda a, b: ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
    a, b, c = mid(p0, p1), mid(p1, p2), mid(p2, p3)
    ab, bc = mid(a, b), mid(b, c)
    m = mid(ab, bc)
    _cubic_flat(p0, a, ab, m, tol, out, depth + 1)
    _cubic_flat(m, bc, c, p3, tol, out, depth + 1)


def _cubic_at(p0, p1, p2, p3, t):
    u = 1 - t
    a, b, c, d = u * u * u, 3 * u * u * t, 3 * u * t * t, t * t * t
    return (a * p0[0] + b * p1[0] + c * p2[0] + d * p3[0], a * p0[1] + b * p1[1] + c * p2[1] + d * p3[1])


def flatten_segment(seg, step, uniform):
    """Points of one segment after its start: adaptive at tolerance `step` px, or with
    `uniform`, samples uniform in the curve parameter about `step` px apart."""
    xy = lambda p: (float(p.x), float(p.y))
    if isinstance(seg, (se.Line, se.Close)):
        return [xy(seg.end)]
    if isinstance(seg, se.Move):
        return []
    if isinstance(seg, se.Arc):
        out = []
        for c in seg.as_cubic_curves():
            out += flatten_segment(c, step, uniform)
        return out
    if isinstance(seg, se.QuadraticBezier):
        p0, q, p3 = xy(seg.start), xy(seg.control), xy(seg.end)
        p1 = (p0[0] + 2 / 3 * (q[0] - p0[0]), p0[1] + 2 / 3 * (q[1] - p0[1]))
        p2 = (p3[0] + 2 / 3 * (q[0] - p3[0]), p3[1] + 2 / 3 * (q[1] - p3[1]))
    else:
        p0, p1, p2, p3 = xy(seg.start), xy(seg.control1), xy(seg.control2), xy(seg.end)
    if uniform:
        length = math.dist(p0, p1) + math.dist(p1, p2) + math.dist(p2, p3)
        n = max(4, min(4000, math.ceil(length / step)))
        return [_cubic_at(p0, p1, p2, p3, i / n) for i in range(1, n + 1)]
    out = []
    _cubic_flat(p0, p1, p2, p3, step, out)
    return out


def rings_of(path, step, uniform=False):
    rings = []
    for sub in path.as_subpaths():
        ring = []
        for seg in sub:
            if isinstance(seg, se.Move):
                ring = [(float(seg.end.x), float(seg.end.y))]
                continue
            ring += flatten_segment(seg, step, uniform)
        pts = ring
        if len(pts) > 1 and pts[0] == pts[-1]:
            pts.pop()
        if len(pts) >= 2:
            rings.append(pts)
    return rings


MERGE = 1e-3  # px: consecutive points closer than this are one (the Rust CONTACT_EPS)


def distinct(pts):
    out = []
    for p in pts:
        if not out or math.dist(out[-1], p) > MERGE:
            out.append(p)
    while len(out) > 1 and math.dist(out[0], out[-1]) <= MERGE:
        out.pop()
    return out


def ring_valid(pts):
    d = distinct(pts)
    if len(d) < 3:
        return False
    return Polygon(d).is_valid


def rings_meet_more_than_once(a, b):
    ra, rb = LinearRing(distinct(a)), LinearRing(distinct(b))
    inter = ra.intersection(rb)
    return not (inter.is_empty or inter.geom_type == "Point")


def has_paint(c):
    return c is not None and getattr(c, "value", None) is not None


def check_file(fname, step, uniform):
    svg = se.SVG.parse(str(fname), reify=True)
    w, h = float(svg.width), float(svg.height)
    paths, bad, first = 0, 0, True
    details = []
    for el in svg.elements():
        if not isinstance(el, se.Shape):
            continue
        filled, stroked = has_paint(el.fill), has_paint(el.stroke)
        if not (filled or stroked):
            continue
        path = se.Path(el)
        path.reify()
        rings = rings_of(path, step, uniform)
        if first:
            first = False
            if filled and rings:
                try:
                    # Area of the first ring's fill inside the canvas (the Rust check
                    # measures the painted coverage, which the canvas clips).
                    d = distinct(rings[0])
                    area = make_valid(Polygon(d)).intersection(box(0, 0, w, h)).area if len(d) >= 3 else 0.0
                except Exception:
                    area = 0.0
                if area >= 0.995 * w * h:
                    continue
        paths += 1
        if not filled:
            continue
        ok = all(ring_valid(r) for r in rings)
        if ok:
            for i in range(len(rings)):
                for j in range(i + 1, len(rings)):
                    if len(distinct(rings[i])) >= 3 and len(distinct(rings[j])) >= 3 and rings_meet_more_than_once(rings[i], rings[j]):
                        ok = False
        if not ok:
            bad += 1
            why = [explain_validity(Polygon(distinct(r))) for r in rings if len(distinct(r)) >= 3 and not ring_valid(r)]
            details.append({"index": paths - 1, "why": why[:1] or ["rings meet"]})
    return {"file": fname.name, "paths": paths, "self_intersecting": bad}, details


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder")
    ap.add_argument("--step", type=float, default=0.01,
                    help="flattening tolerance in px (default 0.01, as the Rust check)")
    ap.add_argument("--uniform", action="store_true",
                    help="sample curves uniformly in t about --step px apart instead (finer: also sees loops smaller than the tolerance)")
    ap.add_argument("--details", action="store_true", help="also print which paths and why")
    a = ap.parse_args()
    total = {"files": 0, "paths": 0, "self_intersecting": 0}
    for f in sorted(FsPath(a.folder).glob("*.svg")):
        r, details = check_file(f, a.step, a.uniform)
        if a.details:
            r["details"] = details
        print(json.dumps(r))
        total["files"] += 1
        total["paths"] += r["paths"]
        total["self_intersecting"] += r["self_intersecting"]
    print(json.dumps({"total": total}))


if __name__ == "__main__":
    sys.exit(main())
