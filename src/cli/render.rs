//! `vectorfusion render IN.svg -o OUT.png [--size N] [--antialias exact|supersampled]`: renders
//! an SVG (or scene JSON) through our own import path and forward rasteriser, so it can be
//! compared with resvg or a browser;
//! `-o OUT.pdf` writes the imported scene as a one-page vector PDF instead ([`crate::pdf`]).
//! What the import could not draw (filters, images it may not read or decode, broken reference
//! cycles) is printed on stderr, one `warning: …` line each. Images are read beside the input
//! file; pattern tiles are drawn at the output's resolution and anti-aliasing.

use super::{CliError, ResultExt as _};
use crate::{raster, svg};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Input SVG (or `.json` scene: the bench format or a serialised `Scene`).
    pub input: PathBuf,
    /// Output: `.png` (or no extension) a PNG, `.pdf` a one-page vector PDF.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Output width in pixels (the height keeps the aspect ratio). Default: the SVG's size.
    #[arg(long)]
    pub size: Option<u32>,
    /// Anti-aliasing of a PNG: `exact` area coverage (the differentiable rasteriser's), or
    /// `supersampled`, 16 samples a pixel on a 4 × 4 grid as resvg (tiny-skia) draws, for
    /// pixel-for-pixel comparisons with it. A PDF is vector and takes none.
    #[arg(long, value_enum, default_value_t = AntialiasArg::Exact)]
    pub antialias: AntialiasArg,
}

/// `--antialias`: [`raster::Antialias`] on the command line.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum AntialiasArg {
    Exact,
    Supersampled,
}

impl From<AntialiasArg> for raster::Antialias {
    fn from(a: AntialiasArg) -> Self {
        match a {
            AntialiasArg::Exact => raster::Antialias::Exact,
            AntialiasArg::Supersampled => raster::Antialias::Supersampled,
        }
    }
}

/// What `render` writes, by the output's extension.
#[derive(Clone, Copy, PartialEq)]
enum Format {
    Png,
    Pdf,
}

impl Format {
    fn of(path: &std::path::Path) -> Result<Format, CliError> {
        match super::output_extension(path).as_deref() {
            None | Some("png") => Ok(Format::Png),
            Some("pdf") => Ok(Format::Pdf),
            Some(other) => Err(CliError::Usage(format!(
                "--output: render writes .png or .pdf, not .{other}"
            ))),
        }
    }
}

pub fn run(args: RenderArgs) -> Result<(), CliError> {
    // The input is the user's: a file that is missing, unreadable or not a valid scene is bad
    // input (2), as README's exit codes say; only writing the output is a runtime failure (1).
    let format = Format::of(&args.output)?;
    let usage = |e: svg::SvgError| CliError::Usage(e.to_string());
    let mut import = svg::load_import(&args.input).map_err(usage)?;
    // Pattern tiles are drawn at the output's resolution and anti-aliasing: import again when
    // they differ from the canvas's.
    let drawn = svg::DrawnAt {
        resolution: match args.size {
            Some(n) if import.scene.width > 0 => n as f32 / import.scene.width as f32,
            _ => 1.0,
        },
        antialias: args.antialias.into(),
    };
    if drawn != svg::DrawnAt::CANVAS {
        import = svg::load_import_at(&args.input, drawn).map_err(usage)?;
    }
    for w in &import.warnings {
        eprintln!("warning: {w}");
    }
    let scene = import.scene;
    let scene = match args.size {
        Some(n) if n == 0 || n > crate::scene::MAX_SIDE => {
            return Err(CliError::Usage(format!(
                "--size must be in 1..={}",
                crate::scene::MAX_SIDE
            )));
        }
        Some(n) => scene.scaled_to_width(n),
        None => scene,
    };
    scene
        .validate()
        .map_err(|e| CliError::Usage(format!("scaled scene is invalid: {e}")))?;
    match format {
        Format::Png => raster::render_with(&scene, args.antialias.into())
            .save_png(&args.output)
            .map_err(|e| CliError::Other(e.into())),
        Format::Pdf => std::fs::write(&args.output, crate::pdf::to_pdf(&scene))
            .failed(|| format!("cannot write {}", args.output.display())),
    }
}
