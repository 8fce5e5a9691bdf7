//! Scene files: the benchmark scene JSON format, and loading a scene (SVG or JSON) from disk with
//! a size cap.

use super::import_pattern::DrawnAt;
use super::{ImageLimits, SvgError, SvgImport, import_svg_in};
use crate::scene::{Point, Rgba, Scene, Shape};
use std::path::Path;

#[derive(serde::Deserialize)]
struct JsonPath {
    points: Vec<[f64; 2]>,
    fill: Vec<f32>,
    #[serde(default = "one")]
    opacity: f32,
}

fn one() -> f32 {
    1.0
}

#[derive(serde::Deserialize)]
struct JsonScene {
    width: u32,
    height: u32,
    #[serde(default)]
    background: Option<[f32; 4]>,
    paths: Vec<JsonPath>,
}

/// Loads the benchmark scene format of `shared/bench/scene64.json`: `width`, `height`,
/// `background` RGBA, `paths` of closed cubic paths (`points` 3n pairs, `fill` RGB or RGBA,
/// `opacity` multiplied into the alpha). Falls back to the serde form of [`Scene`].
pub fn scene_from_json(text: &str) -> Result<Scene, SvgError> {
    let js: JsonScene = match serde_json::from_str(text) {
        Ok(j) => j,
        Err(bench_err) => {
            return match serde_json::from_str::<Scene>(text) {
                Ok(s) => {
                    s.validate()?;
                    Ok(s)
                }
                Err(_) => Err(SvgError::Json(bench_err.to_string())),
            };
        }
    };
    let bg = js.background.unwrap_or([0.0; 4]);
    let mut scene = Scene::new(js.width, js.height, Rgba::from_array(bg))?;
    for (i, p) in js.paths.iter().enumerate() {
        let (r, g, b, a) = match p.fill.as_slice() {
            [r, g, b] => (*r, *g, *b, 1.0),
            [r, g, b, a] => (*r, *g, *b, *a),
            _ => {
                return Err(SvgError::Json(format!(
                    "path {i}: fill needs 3 or 4 channels"
                )));
            }
        };
        let pts = p
            .points
            .iter()
            .map(|q| Point::new(q[0] as f32, q[1] as f32))
            .collect();
        let shape = Shape::closed_cubic(pts, Rgba::new(r, g, b, a * p.opacity))
            .map_err(|e| SvgError::Json(format!("path {i}: {e}")))?;
        scene.shapes.push(shape);
    }
    Ok(scene)
}

/// Loads a scene from a `.json` (bench or serde scene format) or SVG file.
pub fn load_scene(path: &Path) -> Result<Scene, SvgError> {
    load_import(path).map(|i| i.scene)
}

/// [`load_import`] for a scene that will be drawn as `d` says: pattern tiles are drawn alike.
pub fn load_import_at(path: &Path, d: DrawnAt) -> Result<SvgImport, SvgError> {
    super::import_pattern::drawn_at(d, || load_import(path))
}

/// [`load_scene`], with the SVG import's warnings (none for JSON).
pub fn load_import(path: &Path) -> Result<SvgImport, SvgError> {
    let text = read_text_capped(path, SCENE_FILE_MAX_BYTES)?;
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("json"))
    {
        scene_from_json(&text).map(|scene| SvgImport {
            scene,
            warnings: Vec::new(),
        })
    } else {
        import_svg_in(&text, path.parent(), ImageLimits::DEFAULT)
    }
}

/// Largest scene file `load_scene` reads (an SVG is further held to [`SvgLimits::max_bytes`]).
pub const SCENE_FILE_MAX_BYTES: u64 = 64 << 20;

/// Reads SVG text from `path` (UTF-8, UTF-16 by its byte-order mark, or the encoding its XML
/// declaration names: [`super::encoding`]), refusing more than `max` bytes (so `/dev/zero` or a
/// huge file is an error, not unbounded memory).
pub fn read_text_capped(path: &Path, max: u64) -> Result<String, SvgError> {
    let name = || path.display().to_string();
    let bytes = read_bytes_capped(path, max)
        .map_err(|source| SvgError::Io {
            path: name(),
            source,
        })?
        .ok_or_else(|| SvgError::TooLarge { path: name(), max })?;
    super::encoding::decode(&bytes).map_err(|source| SvgError::Text {
        path: name(),
        source,
    })
}

/// The bytes of the file at `path`, `None` when it holds more than `max` (at most `max + 1` are
/// read).
pub(super) fn read_bytes_capped(path: &Path, max: u64) -> std::io::Result<Option<Vec<u8>>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?
        .take(max + 1)
        .read_to_end(&mut bytes)?;
    Ok((bytes.len() as u64 <= max).then_some(bytes))
}
