//! Caption consistency as in VectorFusion's Table 1: for N SVGs generated from N captions,
//!
//! - **CLIP R-Precision**: the share of SVGs whose most similar caption, among all N captions,
//!   is their own;
//! - **CLIP similarity**: the mean cosine similarity ×100 between each SVG and its caption.
//!
//! SVGs are rendered with resvg over white at the scorer's input size, then go through the
//! scorer's reference preprocessing. Style modifiers appended to prompts for generation are
//! stripped from the reference text ([`strip_style`]).

use super::colour::{ColourBinding, colour_binding};
use crate::image::Image;
use crate::models::clip::ClipError;
use crate::models::scorer::clip::dot;
use crate::models::scorer::{ImageTextScorer, ScorerError};
use crate::svg::RenderError;
use resvg::{tiny_skia, usvg};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Errors of the evaluation layer.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: line {line} is empty (every line must hold one caption)")]
    EmptyLine { path: PathBuf, line: usize },
    #[error("{path}: no captions")]
    NoCaptions { path: PathBuf },
    #[error(
        "missing SVG for prompt line {line}: {path} (SVGs are named by prompt line, 0001.svg, 0002.svg, ...)"
    )]
    MissingSvg { path: PathBuf, line: usize },
    #[error("{path}: cannot render SVG: {source}")]
    Svg {
        path: PathBuf,
        #[source]
        source: RenderError,
    },
    #[error("{0} captions but {1} images")]
    CountMismatch(usize, usize),
    #[error(transparent)]
    Clip(#[from] ClipError),
    #[error(transparent)]
    Scorer(#[from] ScorerError),
}

/// Style modifiers VectorFusion (and common text-to-SVG prompts) append to captions.
pub const STYLE_SUFFIXES: &[&str] = &[
    "minimal flat 2d vector icon",
    "minimal flat 2d vector",
    "flat 2d vector icon",
    "vector icon",
    "vector art",
    "lineal color",
    "linear color",
    "on a white background",
    "white background",
    "trending on artstation",
    "pixel art",
    "minimal 2d line drawing",
    "2d line drawing",
    "line drawing",
    "sketch",
    "svg",
];

/// Removes trailing style modifiers (and the punctuation between them) from a prompt, e.g.
/// `"a cat. minimal flat 2d vector icon. lineal color. trending on artstation"` → `"a cat"`.
/// A modifier must follow punctuation; a caption that is nothing but modifiers is kept as is.
pub fn strip_style(prompt: &str) -> String {
    let trim = |s: &str| -> String {
        s.trim_end_matches(|c: char| c.is_whitespace() || ".,;:|-".contains(c))
            .to_string()
    };
    let mut cur = trim(prompt.trim());
    loop {
        let mut changed = false;
        for suf in STYLE_SUFFIXES {
            // Suffixes are ASCII: compare case-insensitively on `cur` itself, so byte offsets
            // stay valid whatever lowercasing would do to the rest of the caption.
            let cut = cur.len().checked_sub(suf.len());
            let head = cut
                .filter(|&c| cur.is_char_boundary(c) && cur[c..].eq_ignore_ascii_case(suf))
                .map(|c| &cur[..c]);
            if let Some(head) = head {
                // Only as a separate phrase: after punctuation (". ", ", "), never inside the
                // caption's own words ("an artist's sketch" keeps its sketch).
                let boundary = head.trim_end().ends_with(|c: char| ".,;:|".contains(c));
                let rest = trim(&cur[..head.len()]);
                if boundary && !rest.is_empty() {
                    cur = rest;
                    changed = true;
                    break;
                }
            }
        }
        if !changed {
            return cur;
        }
    }
}

/// Reads one caption per line. Empty (or whitespace-only) lines are rejected with their line
/// number; a final newline is fine.
pub fn read_prompts(path: &Path) -> Result<Vec<String>, EvalError> {
    let text = std::fs::read_to_string(path).map_err(|source| EvalError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            return Err(EvalError::EmptyLine {
                path: path.to_path_buf(),
                line: i + 1,
            });
        }
        out.push(line.trim().to_string());
    }
    if out.is_empty() {
        return Err(EvalError::NoCaptions {
            path: path.to_path_buf(),
        });
    }
    Ok(out)
}

/// File name of the SVG for 1-based prompt line `line`: `0001.svg`.
pub fn svg_name(line: usize) -> String {
    format!("{line:04}.svg")
}

/// A rendered SVG and its number of paths.
#[derive(Debug, Clone)]
pub struct RenderedSvg {
    pub image: Image,
    pub paths: usize,
}

fn count_paths(g: &usvg::Group) -> usize {
    g.children()
        .iter()
        .map(|n| match n {
            usvg::Node::Group(g) => count_paths(g),
            usvg::Node::Path(_) => 1,
            _ => 0,
        })
        .sum()
}

/// Renders SVG text with resvg over white so that its shorter side is `short_side` pixels.
pub fn render_svg(svg: &str, short_side: u32) -> Result<RenderedSvg, RenderError> {
    let tree = crate::svg::parse_usvg(svg)?;
    let size = tree.size();
    let (w, h) = (size.width(), size.height());
    if !(w > 0.0 && h > 0.0) {
        return Err(RenderError::NoSize);
    }
    let scale = short_side as f32 / w.min(h);
    // Cap the long side: a hostile aspect ratio must not ask for a terabyte pixmap.
    let long = (w.max(h) * scale).round();
    if !long.is_finite() || long > crate::scene::MAX_SIDE as f32 {
        return Err(RenderError::TooExtreme {
            width: w,
            height: h,
            side: short_side,
        });
    }
    let pw = ((w * scale).round() as u32).max(1);
    let ph = ((h * scale).round() as u32).max(1);
    let mut pixmap = crate::svg::pixmap(pw, ph)?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    let data = pixmap
        .data()
        .iter()
        .map(|&b| f32::from(b) / 255.0)
        .collect();
    Ok(RenderedSvg {
        image: Image {
            width: pw,
            height: ph,
            data,
        },
        paths: count_paths(tree.root()),
    })
}

/// The side (px) SVGs are rendered at for colour binding.
pub const COLOUR_SIDE: u32 = 64;

/// Reads and renders `dir/0001.svg`… for `n` prompts.
pub fn render_svg_dir(
    dir: &Path,
    n: usize,
    short_side: u32,
) -> Result<Vec<RenderedSvg>, EvalError> {
    (1..=n)
        .map(|line| {
            let path = dir.join(svg_name(line));
            if !path.is_file() {
                return Err(EvalError::MissingSvg { path, line });
            }
            let text = std::fs::read_to_string(&path).map_err(|source| EvalError::Io {
                path: path.clone(),
                source,
            })?;
            render_svg(&text, short_side).map_err(|source| EvalError::Svg { path, source })
        })
        .collect()
}

/// Per-SVG result for one scorer.
#[derive(Debug, Clone, Serialize)]
pub struct SvgScore {
    /// 1-based prompt line.
    pub line: usize,
    /// Cosine similarity ×100 with its own caption.
    pub similarity: f32,
    /// 1-based line of the most similar caption.
    pub best_line: usize,
    /// Whether the most similar caption is its own.
    pub hit: bool,
}

/// One scorer's row of the table.
#[derive(Debug, Clone, Serialize)]
pub struct ScorerResult {
    pub scorer: String,
    /// In [0, 1].
    pub r_precision: f64,
    /// Mean cosine similarity ×100.
    pub mean_similarity: f64,
    pub per_svg: Vec<SvgScore>,
}

/// R-Precision and mean similarity from unit image and caption embeddings (`images[i]` was
/// generated from `captions[i]`).
pub fn score_embeddings(scorer: &str, images: &[Vec<f32>], captions: &[Vec<f32>]) -> ScorerResult {
    let per_svg: Vec<SvgScore> = images
        .iter()
        .enumerate()
        .map(|(i, im)| {
            let sims: Vec<f32> = captions.iter().map(|c| dot(im, c)).collect();
            let mut best = 0;
            for (j, &s) in sims.iter().enumerate() {
                if s > sims[best] {
                    best = j;
                }
            }
            SvgScore {
                line: i + 1,
                similarity: 100.0 * sims.get(i).copied().unwrap_or(f32::NAN),
                best_line: best + 1,
                hit: best == i,
            }
        })
        .collect();
    let n = per_svg.len().max(1) as f64;
    ScorerResult {
        scorer: scorer.to_string(),
        r_precision: per_svg.iter().filter(|s| s.hit).count() as f64 / n,
        mean_similarity: per_svg.iter().map(|s| f64::from(s.similarity)).sum::<f64>() / n,
        per_svg,
    }
}

/// Evaluates images (index i generated from caption i) with one scorer.
pub fn evaluate<S: ImageTextScorer + ?Sized>(
    scorer: &S,
    captions: &[String],
    images: &[Image],
) -> Result<ScorerResult, EvalError> {
    if captions.len() != images.len() {
        return Err(EvalError::CountMismatch(captions.len(), images.len()));
    }
    let refs: Vec<String> = captions.iter().map(|c| strip_style(c)).collect();
    let refs: Vec<&str> = refs.iter().map(String::as_str).collect();
    let t = scorer.text_embeddings(&refs)?;
    let i = scorer.image_embeddings(images)?;
    Ok(score_embeddings(scorer.name(), &i, &t))
}

/// The whole evaluation of one method (or SVG directory) with several scorers.
#[derive(Debug, Clone, Serialize)]
pub struct EvalReport {
    /// Method name, or `svgs:<dir>`.
    pub method: String,
    pub prompts: usize,
    /// Mean number of paths per SVG.
    pub mean_paths: f64,
    /// Mean generation seconds per SVG, when known (not for pre-generated SVGs).
    pub mean_seconds: Option<f64>,
    pub scorers: Vec<ScorerResult>,
    /// For captions that name a colour: how many pictures are of it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub colour_binding: Option<ColourBinding>,
}

/// Evaluates `dir/0001.svg`… against the captions with every scorer (each renders at its own
/// input size).
pub fn evaluate_svg_dir<S: ImageTextScorer>(
    captions: &[String],
    dir: &Path,
    scorers: &[S],
) -> Result<EvalReport, EvalError> {
    let mut results = Vec::with_capacity(scorers.len());
    let mut mean_paths = 0.0;
    for s in scorers {
        let rendered = render_svg_dir(dir, captions.len(), s.image_size())?;
        mean_paths =
            rendered.iter().map(|r| r.paths as f64).sum::<f64>() / rendered.len().max(1) as f64;
        let images: Vec<Image> = rendered.into_iter().map(|r| r.image).collect();
        results.push(evaluate(s, captions, &images)?);
    }
    // Colour binding at the embedded model's side; also the path count without scorers.
    let rendered = render_svg_dir(dir, captions.len(), COLOUR_SIDE)?;
    if scorers.is_empty() {
        mean_paths =
            rendered.iter().map(|r| r.paths as f64).sum::<f64>() / rendered.len().max(1) as f64;
    }
    let images: Vec<Image> = rendered.into_iter().map(|r| r.image).collect();
    Ok(EvalReport {
        method: format!("svgs:{}", dir.display()),
        prompts: captions.len(),
        mean_paths,
        mean_seconds: None,
        scorers: results,
        colour_binding: colour_binding(captions, &images),
    })
}

/// Formats the report like the paper's Table 1.
pub fn format_table(r: &EvalReport) -> String {
    let mut s = String::new();
    let secs = r
        .mean_seconds
        .map_or("n/a".to_string(), |v| format!("{v:.1}"));
    s.push_str(&format!(
        "method: {}  ({} prompts, {:.1} paths/SVG, {} s/SVG)\n",
        r.method, r.prompts, r.mean_paths, secs
    ));
    let w = r
        .scorers
        .iter()
        .map(|x| x.scorer.chars().count())
        .max()
        .unwrap_or(6)
        .max(6);
    s.push_str(&format!(
        "{:<w$}  {:>11}  {:>15}\n",
        "scorer", "R-Precision", "CLIP similarity"
    ));
    for x in &r.scorers {
        s.push_str(&format!(
            "{:<w$}  {:>10.1}%  {:>15.2}\n",
            x.scorer,
            100.0 * x.r_precision,
            x.mean_similarity
        ));
    }
    if let Some(c) = &r.colour_binding {
        s.push_str(&format!("colour binding: {c}\n"));
    }
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn strip_style_survives_text_that_grows_when_lowercased() {
        // 'İ' lowercases to two chars (3 bytes): byte offsets from a lowercased copy would
        // not fit the original.
        assert_eq!(super::strip_style("İİİİ. svg"), "İİİİ");
        assert_eq!(super::strip_style("İİ cat. Vector Art"), "İİ cat");
    }

    #[test]
    fn extreme_aspect_ratio_svg_is_an_error() {
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="0.01" height="100000"/>"#;
        assert!(super::render_svg(svg, 224).is_err());
    }

    use super::*;

    #[test]
    fn strips_vectorfusion_modifiers_only_at_the_end() {
        assert_eq!(
            strip_style(
                "a cat. minimal flat 2d vector icon. lineal color. on a white background. trending on artstation"
            ),
            "a cat"
        );
        assert_eq!(strip_style("a pixel art robot"), "a pixel art robot");
        assert_eq!(strip_style("A robot, pixel art."), "A robot");
        assert_eq!(strip_style("pixel art"), "pixel art");
        assert_eq!(strip_style("  自転車  "), "自転車");
        assert_eq!(strip_style("an artist's sketch"), "an artist's sketch");
        assert_eq!(strip_style("a dog | svg"), "a dog");
    }

    #[test]
    fn r_precision_counts_own_caption_wins() {
        let e = |v: [f32; 2]| v.to_vec();
        let caps = vec![e([1.0, 0.0]), e([0.0, 1.0]), e([0.6, 0.8])];
        let imgs = vec![e([1.0, 0.0]), e([1.0, 0.0]), e([0.6, 0.8])];
        let r = score_embeddings("t", &imgs, &caps);
        assert!((r.r_precision - 2.0 / 3.0).abs() < 1e-9);
        assert_eq!(r.per_svg[1].best_line, 1);
        assert!((r.mean_similarity - (100.0 + 0.0 + 100.0) / 3.0).abs() < 1e-4);
    }
}
