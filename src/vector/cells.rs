//! Pixel-art cells merged into regions: a scene drawn as a grid of squares (the `pixel_art`
//! style) is written with one outline per 4-connected region of one colour instead of one
//! square per cell, so a designer selects a region, not 30 squares of it.
//!
//! Applies only when every shape is a grid cell ([`grid_of`]): an axis-aligned square
//! [`ShapeKind::Polygon`] of one common side, on one grid, without stroke or gradient, no two
//! in one place. Cells never overlap, so their paint order is free; merged regions are painted
//! largest filled outline first.
//!
//! Each region becomes the outer outline(s) of its cells: the cells' clockwise edges, those
//! shared by two cells of the region cancelled, the rest chained into loops. Where the region
//! touches itself at a corner, the chain turns toward the outside cell it runs along, so every
//! outline is simple (the outer outline and a hole's meet at that corner). Holes are not
//! cut: a hole of a region is filled by its outline and the regions inside it are painted
//! after it (a filled outline holds the filled outline of every region inside it, so painting
//! larger filled areas first is the nesting order). A region with a hole that no opaque cell
//! hides (an empty grid place, a translucent cell) is written as rectangles instead: its rows'
//! runs of cells, runs of one span in consecutive rows joined. The render is the same where
//! cells meet the pixel grid, and has no seams between cells of one colour where they do not.

use crate::scene::{Point, Rgba, Scene, Shape, ShapeKind};
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

/// How far (in cells) a corner may lie off the grid, or a side differ from the common side.
const GRID_TOLERANCE: f32 = 1e-3;

/// A scene's cells on their grid: the side and origin, and each cell's grid place and shape.
struct Grid {
    side: f32,
    origin: (f32, f32),
    cells: HashMap<(i32, i32), usize>,
}

/// The scene's shapes as grid cells, when every shape is one (see the module docs).
fn grid_of(scene: &Scene) -> Option<Grid> {
    let first = scene.shapes.first()?;
    let side = square_of(first)?.2;
    let origin = scene
        .shapes
        .iter()
        .try_fold((f32::INFINITY, f32::INFINITY), |(x, y), s| {
            let (sx, sy, _) = square_of(s)?;
            Some((x.min(sx), y.min(sy)))
        })?;
    let mut cells = HashMap::with_capacity(scene.shapes.len());
    for (i, s) in scene.shapes.iter().enumerate() {
        let (x, y, d) = square_of(s)?;
        let on_grid = |v: f32, o: f32| {
            let k = (v - o) / side;
            ((k - k.round()).abs() <= GRID_TOLERANCE).then_some(k.round() as i32)
        };
        if (d - side).abs() > GRID_TOLERANCE * side {
            return None;
        }
        let place = (on_grid(x, origin.0)?, on_grid(y, origin.1)?);
        if cells.insert(place, i).is_some() {
            return None;
        }
    }
    Some(Grid {
        side,
        origin,
        cells,
    })
}

/// `(x, y, side)` of a shape that is an axis-aligned square cell: a flat-filled 4-gon without
/// stroke or gradient, corners in [`Shape::square`]'s order.
fn square_of(s: &Shape) -> Option<(f32, f32, f32)> {
    if s.kind != ShapeKind::Polygon
        || s.stroke.is_some()
        || s.gradients.is_some()
        || s.fill.is_none()
        || s.points.len() != 4
    {
        return None;
    }
    let p = &s.points;
    let side = p[1].x - p[0].x;
    let tol = GRID_TOLERANCE * side.abs();
    let near = |a: f32, b: f32| (a - b).abs() <= tol;
    let square = side > 0.0
        && near(p[1].y, p[0].y)
        && near(p[2].x, p[1].x)
        && near(p[2].y - p[1].y, side)
        && near(p[3].x, p[0].x)
        && near(p[3].y, p[2].y);
    square.then_some((p[0].x, p[0].y, side))
}

/// One region: its cells, how many places it fills (its cells and the places its holes
/// enclose), the first shape of its cells, and whether its holes may be filled.
struct Region {
    cells: Vec<(i32, i32)>,
    filled: usize,
    first_shape: usize,
    holes_filled: bool,
}

/// Merges the cells of a pixel-art scene into one outline per region of one colour (see the
/// module docs); returns how many paths went (0 when the scene is not a grid of cells).
pub fn merge_cells(scene: &mut Scene) -> usize {
    let Some(grid) = grid_of(scene) else {
        return 0;
    };
    // The fill as the SVG writes it: cells that look alike merge.
    let key_of = |place: &(i32, i32)| {
        grid.cells
            .get(place)
            .and_then(|&i| scene.shapes[i].fill)
            .map(|c| crate::svg::written_color(c, super::export::MAX_DECIMALS))
    };
    let regions = regions(&grid, key_of);
    let before = scene.shapes.len();
    let mut order: Vec<&Region> = regions.iter().collect();
    // Larger filled outlines first (they hold the regions inside their holes); ties in the
    // order the cells were drawn, so the result is deterministic.
    order.sort_by_key(|r| (std::cmp::Reverse(r.filled), r.first_shape));
    let mut shapes = Vec::with_capacity(before);
    for r in order {
        let template = &scene.shapes[r.first_shape];
        let pieces = if r.holes_filled {
            outlines(&r.cells)
        } else {
            rectangles(&r.cells)
        };
        let polygons: Result<Vec<Shape>, _> = pieces
            .iter()
            .map(|outline| {
                let points = outline
                    .iter()
                    .map(|&(x, y)| Point {
                        x: grid.origin.0 + x as f32 * grid.side,
                        y: grid.origin.1 + y as f32 * grid.side,
                    })
                    .collect();
                let s = Shape::polygon(points, template.fill.unwrap_or(Rgba::TRANSPARENT))?;
                Ok::<_, crate::scene::SceneError>(Shape {
                    stage: template.stage,
                    ..s
                })
            })
            .collect();
        match polygons {
            Ok(p) => shapes.extend(p),
            // An outline the scene cannot hold (it cannot happen for grid corners): the
            // region's cells as they were.
            Err(_) => shapes.extend(r.cells.iter().map(|p| scene.shapes[grid.cells[p]].clone())),
        }
    }
    scene.shapes = shapes;
    before.saturating_sub(scene.shapes.len())
}

/// The 4-connected regions of equal colour key, each with its filled area (cells and holes)
/// and whether every hole place holds an opaque cell.
fn regions(grid: &Grid, key_of: impl Fn(&(i32, i32)) -> Option<Rgba>) -> Vec<Region> {
    let mut places: Vec<(i32, i32)> = grid.cells.keys().copied().collect();
    places.sort_by_key(|p| grid.cells[p]);
    let mut seen: HashSet<(i32, i32)> = HashSet::with_capacity(places.len());
    let mut out = Vec::new();
    for start in places {
        if !seen.insert(start) {
            continue;
        }
        let key = key_of(&start);
        let mut cells = vec![start];
        let mut i = 0;
        while i < cells.len() {
            let (x, y) = cells[i];
            for n in [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)] {
                if grid.cells.contains_key(&n) && key_of(&n) == key && seen.insert(n) {
                    cells.push(n);
                }
            }
            i += 1;
        }
        let opaque = |p: &(i32, i32)| key_of(p).is_some_and(|c| c.a >= 1.0);
        let (holes, holes_filled) = holes_of(&cells, opaque);
        let first_shape = cells.iter().map(|p| grid.cells[p]).min().unwrap_or(0);
        out.push(Region {
            filled: cells.len() + holes,
            cells,
            first_shape,
            holes_filled,
        });
    }
    out
}

/// How many grid places `cells` enclose (not reachable from outside their box through
/// 4-connected places outside the region), and whether `occupied` holds for all of them (an
/// opaque cell: what is painted over a filled hole must hide it).
fn holes_of(cells: &[(i32, i32)], occupied: impl Fn(&(i32, i32)) -> bool) -> (usize, bool) {
    let (mut x0, mut y0, mut x1, mut y1) = (i32::MAX, i32::MAX, i32::MIN, i32::MIN);
    for &(x, y) in cells {
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    // The box grown by one place: its ring is outside the region and connects the outside.
    let (x0, y0, x1, y1) = (x0 - 1, y0 - 1, x1 + 1, y1 + 1);
    let w = (x1 - x0 + 1) as usize;
    let h = (y1 - y0 + 1) as usize;
    let idx = |(x, y): (i32, i32)| (y - y0) as usize * w + (x - x0) as usize;
    let mut region = vec![false; w * h];
    for &c in cells {
        region[idx(c)] = true;
    }
    let mut outside = vec![false; w * h];
    let mut stack = vec![(x0, y0)];
    outside[0] = true;
    while let Some((x, y)) = stack.pop() {
        for n in [(x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)] {
            if n.0 < x0 || n.0 > x1 || n.1 < y0 || n.1 > y1 {
                continue;
            }
            let i = idx(n);
            if !region[i] && !outside[i] {
                outside[i] = true;
                stack.push(n);
            }
        }
    }
    let mut holes = 0;
    let mut filled = true;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let i = idx((x, y));
            if !region[i] && !outside[i] {
                holes += 1;
                filled &= occupied(&(x, y));
            }
        }
    }
    (holes, filled)
}

/// The outer outlines of a 4-connected set of unit cells, as grid corners in clockwise order
/// (y down), without collinear corners: hole outlines are left out.
fn outlines(cells: &[(i32, i32)]) -> Vec<Vec<(i32, i32)>> {
    // Each cell's clockwise edges; an edge and its reverse (two cells of the region side by
    // side) cancel.
    let mut edges: BTreeSet<((i32, i32), (i32, i32))> = BTreeSet::new();
    for &(x, y) in cells {
        let corners = [(x, y), (x + 1, y), (x + 1, y + 1), (x, y + 1)];
        for k in 0..4 {
            let (a, b) = (corners[k], corners[(k + 1) % 4]);
            if !edges.remove(&(b, a)) {
                edges.insert((a, b));
            }
        }
    }
    let mut from: BTreeMap<(i32, i32), Vec<(i32, i32)>> = BTreeMap::new();
    for &(a, b) in &edges {
        from.entry(a).or_default().push(b);
    }
    let mut loops = Vec::new();
    while let Some((&start, outs)) = from.iter_mut().find(|(_, v)| !v.is_empty()) {
        let first = outs.swap_remove(0);
        let mut lp = vec![start];
        let (mut at, mut dir) = (first, (first.0 - start.0, first.1 - start.1));
        loop {
            // Where the region touches itself at a corner (two edges leave it), turn left: the
            // outline keeps to the one cell outside the region it runs along, so the outer
            // outline and a hole's meet there without either touching itself.
            let left = (dir.1, -dir.0);
            let outs = from.get_mut(&at).filter(|o| !o.is_empty());
            let k = outs
                .as_ref()
                .and_then(|o| o.iter().position(|&b| (b.0 - at.0, b.1 - at.1) == left));
            // Back at the start, the loop closes unless the turn leads along another edge.
            if at == start && k.is_none() {
                break;
            }
            let Some(outs) = outs else { break };
            lp.push(at);
            let next = outs.swap_remove(k.unwrap_or(0));
            dir = (next.0 - at.0, next.1 - at.1);
            at = next;
        }
        loops.push(lp);
    }
    loops
        .into_iter()
        .filter(|lp| signed_area(lp) > 0)
        .map(|lp| without_collinear(&lp))
        .collect()
}

/// A region whose holes cannot be filled, as rectangles: each row's runs of cells, runs of the
/// same span in consecutive rows joined, as clockwise corner loops.
fn rectangles(cells: &[(i32, i32)]) -> Vec<Vec<(i32, i32)>> {
    let mut sorted = cells.to_vec();
    sorted.sort_by_key(|&(x, y)| (y, x));
    // Runs `(y, x0, x1)`, in row order.
    let mut runs: Vec<(i32, i32, i32)> = Vec::new();
    for (x, y) in sorted {
        match runs.last_mut() {
            Some(r) if r.0 == y && r.2 == x => r.2 = x + 1,
            _ => runs.push((y, x, x + 1)),
        }
    }
    // Open rectangles by span: `(x0, x1) -> (top row, last row)`.
    let mut open: BTreeMap<(i32, i32), (i32, i32)> = BTreeMap::new();
    let mut done = Vec::new();
    for (y, x0, x1) in runs {
        match open.get_mut(&(x0, x1)) {
            Some(r) if r.1 + 1 == y => r.1 = y,
            _ => {
                if let Some((top, last)) = open.insert((x0, x1), (y, y)) {
                    done.push((x0, x1, top, last));
                }
            }
        }
    }
    done.extend(open.into_iter().map(|((x0, x1), (t, l))| (x0, x1, t, l)));
    done.sort_by_key(|&(x0, _, top, _)| (top, x0));
    done.into_iter()
        .map(|(x0, x1, top, last)| vec![(x0, top), (x1, top), (x1, last + 1), (x0, last + 1)])
        .collect()
}

/// Twice the signed area of a loop of corners (positive: clockwise with y down, as a cell's).
fn signed_area(lp: &[(i32, i32)]) -> i64 {
    let n = lp.len();
    (0..n)
        .map(|i| {
            let (a, b) = (lp[i], lp[(i + 1) % n]);
            i64::from(a.0) * i64::from(b.1) - i64::from(b.0) * i64::from(a.1)
        })
        .sum()
}

/// The loop's corners where its direction changes.
fn without_collinear(lp: &[(i32, i32)]) -> Vec<(i32, i32)> {
    let n = lp.len();
    (0..n)
        .filter(|&i| {
            let (p, c, q) = (lp[(i + n - 1) % n], lp[i], lp[(i + 1) % n]);
            (c.0 - p.0) * (q.1 - c.1) != (c.1 - p.1) * (q.0 - c.0)
        })
        .map(|i| lp[i])
        .collect()
}

#[cfg(test)]
#[path = "tests_cells.rs"]
mod tests;
