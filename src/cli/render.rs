//! `vectorfusion render IN.svg -o OUT.png [--size N]`: renders an SVG (or scene JSON) through
//! our own import path and forward rasteriser, so it can be compared with resvg or a browser;
//! `-o OUT.pdf` writes the imported scene as a one-page vector PDF instead ([`crate::pdf`]).
//! What the import could not draw (filters, images it may not read or decode, broken reference
//! cycles) is printed on stderr, one `warning: …` line each. Images are read beside the input
//! file; pattern tiles are drawn at the output's resolution.

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
    // Pattern tiles are drawn at the output's resolution: import again when it differs.
    if let Some(n) = args.size {
        let res = n as f32 / import.scene.width as f32;
        if res != 1.0 && import.scene.width > 0 {
            import = svg::load_import_at(&args.input, res).map_err(usage)?;
        }
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
        Format::Png => raster::render(&scene)
            .save_png(&args.output)
            .map_err(|e| CliError::Other(e.into())),
        Format::Pdf => std::fs::write(&args.output, crate::pdf::to_pdf(&scene))
            .failed(|| format!("cannot write {}", args.output.display())),
    }
}
