//! One image traced by every tool of an R–D run, each SVG scored against it.

use super::peers::{ImageTracer, imagetracer_grid, potrace_grid, run_potrace, to_pbm};
use super::{Grid, RdSample, VtInput, editability};
use crate::cli::{CliError, ResultExt};
use crate::image::ssim::ssim_over_white;
use crate::image::{Image, psnr};
use crate::progress::{CancelToken, NullSink};
use crate::stages::live::tracer::{TracerSetting, render_svg, trace};
use crate::stages::live::{self, LiveConfig};
use std::io::Write;
use std::path::Path;
use std::time::Instant;

/// One image of a set, the target every tool's SVG is scored against.
pub(super) struct Target<'a> {
    pub set: &'a str,
    pub image: String,
    pub target: &'a Image,
}

impl Target<'_> {
    /// vtracer: spline and polygon × speckle × precision on each input of `--vt-input`.
    pub fn vtracer(&self, grid: &Grid) -> Result<Vec<RdSample>, CliError> {
        let white = self.target.over([1.0, 1.0, 1.0]);
        let mut inputs: Vec<(&Image, &str)> = Vec::new();
        if grid.vt_input != VtInput::White {
            inputs.push((self.target, ""));
        }
        if grid.vt_input != VtInput::Rgba {
            inputs.push((&white, " white"));
        }
        let mut out = Vec::new();
        for (input, suffix) in inputs {
            for polygon in [false, true] {
                for &filter_speckle in &grid.speckles {
                    for &color_precision in &grid.precisions {
                        let s = TracerSetting {
                            polygon,
                            filter_speckle,
                            color_precision,
                            ..TracerSetting::default()
                        };
                        let t0 = Instant::now();
                        let svg = trace(input, &s)
                            .map_err(anyhow::Error::msg)
                            .failed(|| format!("{}: vtracer", self.image))?
                            .svg;
                        let secs = t0.elapsed().as_secs_f64();
                        let label = format!("{}{suffix}", s.label());
                        out.push(self.score("vtracer", &label, &svg, secs)?);
                    }
                }
            }
        }
        Ok(out)
    }

    /// imagetracer's grid on the PNG file itself (the driver composes it over white).
    pub fn imagetracer(
        &self,
        tracer: &ImageTracer,
        file: &Path,
        colors: &[usize],
    ) -> Result<Vec<RdSample>, CliError> {
        let mut out = Vec::new();
        for (label, options) in imagetracer_grid(colors) {
            let (svg, secs) = tracer
                .run(file, &options)
                .failed(|| format!("{}: {label}", self.image))?;
            out.push(self.score("imagetracer", &label, &svg, secs)?);
        }
        Ok(out)
    }

    /// potrace's grid on the image thresholded to black and white.
    pub fn potrace(&self, bin: &str) -> Result<Vec<RdSample>, CliError> {
        let pbm = to_pbm(self.target);
        let mut out = Vec::new();
        for (label, args) in potrace_grid() {
            let (svg, secs) = run_potrace(bin, &pbm, &args)
                .failed(|| format!("{}: potrace {label}", self.image))?;
            out.push(self.score("potrace", &label, &svg, secs)?);
        }
        Ok(out)
    }

    /// Our LIVE run `label`, written as every run writes it (fewest decimals within the render
    /// tolerance, simple outlines) and timed with the tracing.
    pub fn live(&self, label: &str, cfg: &LiveConfig) -> Result<RdSample, CliError> {
        let t0 = Instant::now();
        let res = live::vectorize(self.target, cfg, &NullSink, &CancelToken::new())
            .failed(|| format!("{}: live {label}", self.image))?;
        let svg = crate::vector::write_svg(&res.scene, &cfg.colors);
        let secs = t0.elapsed().as_secs_f64();
        let s = self.score("live", label, &svg, secs)?;
        eprintln!(
            "{}/{}: live {label:9} paths {:3} psnr {:6.2} ssim {:.4} bytes {:6} gz {:5} {:.2} s",
            self.set, self.image, s.paths, s.psnr, s.ssim, s.svg_bytes, s.svg_gz_bytes, s.seconds
        );
        Ok(s)
    }

    /// Scores one SVG against the target.
    fn score(
        &self,
        tool: &str,
        setting: &str,
        svg: &str,
        seconds: f64,
    ) -> Result<RdSample, CliError> {
        let back = render_svg(svg, self.target.width, self.target.height)
            .failed(|| format!("{}: {tool} {setting}: cannot render", self.image))?;
        Ok(RdSample {
            set: self.set.to_string(),
            image: self.image.clone(),
            tool: tool.to_string(),
            setting: setting.to_string(),
            paths: svg.matches("<path").count(),
            psnr: psnr(self.target, &back),
            ssim: ssim_over_white(self.target, &back),
            svg_bytes: svg.len(),
            svg_gz_bytes: gzip_len(svg),
            seconds,
            editability: editability(svg),
        })
    }
}

fn gzip_len(text: &str) -> usize {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to a Vec cannot fail.
    let _ = enc.write_all(text.as_bytes());
    enc.finish().map(|v| v.len()).unwrap_or(0)
}
