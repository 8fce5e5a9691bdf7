//! Where an imported `<image>` may come from, and the bounds on decoding it (the image part of
//! the guard).
//!
//! - `data:` URLs: PNG (8/16-bit, luma, palette), JPEG, GIF (first frame) and WebP by their
//!   MIME type, or sniffed from the bytes when the type is missing or wrong; `image/svg+xml`
//!   (gzip-compressed too) is parsed by the guard again, at most [`ImageLimits::max_svg_depth`]
//!   SVG images deep (deeper ones are dropped).
//! - other `href`s are files, read only when the caller names the directory of the SVG file
//!   (the command line reading a file): relative paths from there, at most
//!   [`ImageLimits::max_bytes`] read; never from inside an SVG image (as usvg, which resolves
//!   only `data:` URLs there). Everywhere else (the service, every text input) nothing is
//!   read and the image is dropped with a warning naming its `href`.
//! - an image declaring more than [`ImageLimits::max_pixels`] pixels, or more than
//!   [`ImageLimits::max_total_pixels`] over the whole import, is dropped with a warning before
//!   it is decoded; decoding itself runs under the `image` crate's allocation limit, so a
//!   decompression bomb is refused, never a panic or unbounded memory.

use super::guard::{self, Parsed, SvgLimits, SvgRejected};
use resvg::usvg;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use usvg::ImageKind;

/// The bounds on images (part of the guard; stated in docs/SERVICE.md).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageLimits {
    /// Encoded bytes of one image (a file read or an SVG image inflated).
    pub max_bytes: u64,
    /// Pixels of one decoded image.
    pub max_pixels: u64,
    /// Pixels of all decoded images of one import.
    pub max_total_pixels: u64,
    /// Bytes the decoder may allocate for one image.
    pub max_alloc: u64,
    /// SVG images inside SVG images (1: an SVG image may hold raster images only).
    pub max_svg_depth: u32,
}

impl ImageLimits {
    pub const DEFAULT: ImageLimits = ImageLimits {
        max_bytes: 16 << 20,
        max_pixels: 4096 * 4096,
        max_total_pixels: 2 * 4096 * 4096,
        max_alloc: 256 << 20,
        max_svg_depth: 2,
    };
}

/// One import's image sources and budget, shared by the resolvers of nested SVG images.
pub(super) struct Images {
    base_dir: Option<PathBuf>,
    /// The fonts text is laid out with (see `fonts`).
    fonts: Arc<usvg::fontdb::Database>,
    limits: ImageLimits,
    pixels: AtomicU64,
    warnings: Mutex<Vec<String>>,
}

impl Images {
    pub(super) fn new(
        base_dir: Option<&Path>,
        limits: ImageLimits,
        fonts: Arc<usvg::fontdb::Database>,
    ) -> Self {
        Images {
            base_dir: base_dir.map(Path::to_path_buf),
            fonts,
            limits,
            pixels: AtomicU64::new(0),
            warnings: Mutex::new(Vec::new()),
        }
    }

    /// Whether any font is loaded (usvg drops every text without one).
    pub(super) fn has_fonts(&self) -> bool {
        self.fonts.faces().next().is_some()
    }

    fn warn(&self, w: String) {
        if let Ok(mut v) = self.warnings.lock() {
            v.push(w);
        }
    }

    /// The warnings so far (the resolvers run inside usvg's parse).
    pub(super) fn take_warnings(&self) -> Vec<String> {
        self.warnings
            .lock()
            .map(|mut v| std::mem::take(&mut *v))
            .unwrap_or_default()
    }

    /// Parses `text` through the guard with this import's image resolvers, `depth` SVG images
    /// deep.
    pub(super) fn parse(&self, text: &str, depth: u32) -> Result<Parsed, SvgRejected> {
        let opts = usvg::Options {
            image_href_resolver: usvg::ImageHrefResolver {
                resolve_data: Box::new(move |mime, data, _| self.data(mime, &data, depth)),
                resolve_string: Box::new(move |href, _| self.file(href, depth)),
            },
            fontdb: Arc::clone(&self.fonts),
            ..usvg::Options::default()
        };
        guard::parse_repaired(text, &SvgLimits::DEFAULT, &opts)
    }

    fn data(&self, mime: &str, data: &[u8], depth: u32) -> Option<ImageKind> {
        let svg = mime == "image/svg+xml" || sniff(data).is_none() && looks_like_svg(data);
        if svg {
            return self.svg(data, depth, "a data: URL");
        }
        self.raster(data, "a data: URL")
    }

    fn file(&self, href: &str, depth: u32) -> Option<ImageKind> {
        if depth > 0 {
            // As usvg: an SVG image is drawn from its own bytes, so a file it names (itself, too)
            // is not read.
            self.warn(format!(
                "<image href=\"{}\"> inside an SVG image dropped (an SVG image reads no files)",
                clip_text(href)
            ));
            return None;
        }
        let Some(dir) = &self.base_dir else {
            self.warn(format!(
                "<image href=\"{}\"> dropped (external images are read only from an SVG file \
                 named on the command line)",
                clip_text(href)
            ));
            return None;
        };
        let path = dir.join(href);
        let max = self.limits.max_bytes;
        let read = super::file::read_bytes_capped(&path, max).map_err(ImageError::Read);
        let bytes = match read.and_then(|b| b.ok_or(ImageError::TooLarge(max))) {
            Ok(b) => b,
            Err(e) => {
                self.warn(format!("<image href=\"{}\"> dropped: {e}", clip_text(href)));
                return None;
            }
        };
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext.eq_ignore_ascii_case("svg") || ext.eq_ignore_ascii_case("svgz") {
            return self.svg(&bytes, depth, href);
        }
        self.raster(&bytes, href)
    }

    /// A raster image, if its format is known and its declared size within the budget.
    fn raster(&self, data: &[u8], from: &str) -> Option<ImageKind> {
        let Some(format) = sniff(data) else {
            self.warn(format!(
                "<image> from {} dropped: not a PNG, JPEG, GIF, WebP or SVG image",
                clip_text(from)
            ));
            return None;
        };
        let dims = image::ImageReader::with_format(std::io::Cursor::new(data), format)
            .into_dimensions()
            .ok()?;
        let px = u64::from(dims.0) * u64::from(dims.1);
        let l = &self.limits;
        let total = self.pixels.fetch_add(px, Ordering::Relaxed) + px;
        if px > l.max_pixels || total > l.max_total_pixels {
            self.warn(format!(
                "<image> from {} dropped: {}x{} pixels is over the limit ({} per image, {} per \
                 SVG)",
                clip_text(from),
                dims.0,
                dims.1,
                l.max_pixels,
                l.max_total_pixels
            ));
            return None;
        }
        let data = Arc::new(data.to_vec());
        Some(match format {
            image::ImageFormat::Jpeg => ImageKind::JPEG(data),
            image::ImageFormat::Gif => ImageKind::GIF(data),
            image::ImageFormat::WebP => ImageKind::WEBP(data),
            _ => ImageKind::PNG(data),
        })
    }

    /// An SVG image (gzip-compressed too), parsed by the guard one level deeper.
    fn svg(&self, data: &[u8], depth: u32, from: &str) -> Option<ImageKind> {
        if depth >= self.limits.max_svg_depth {
            self.warn(format!(
                "SVG <image> from {} dropped: SVG images nest at most {} deep",
                clip_text(from),
                self.limits.max_svg_depth
            ));
            return None;
        }
        let text = match inflate(data, self.limits.max_bytes) {
            Ok(t) => t,
            Err(e) => {
                self.warn(format!("SVG <image> from {} dropped: {e}", clip_text(from)));
                return None;
            }
        };
        match self.parse(&text, depth + 1) {
            Ok(p) => Some(ImageKind::SVG(p.tree)),
            Err(e) => {
                self.warn(format!("SVG <image> from {} dropped: {e}", clip_text(from)));
                None
            }
        }
    }

    /// Decodes a raster image into premultiplied RGBA8 (first frame of a GIF), under the
    /// allocation limit.
    pub(super) fn decode(&self, kind: &ImageKind) -> Result<(u32, u32, Vec<u8>), ImageError> {
        let (data, format) = match kind {
            ImageKind::PNG(d) => (d, image::ImageFormat::Png),
            ImageKind::JPEG(d) => (d, image::ImageFormat::Jpeg),
            ImageKind::GIF(d) => (d, image::ImageFormat::Gif),
            ImageKind::WEBP(d) => (d, image::ImageFormat::WebP),
            ImageKind::SVG(_) => return Err(ImageError::NotRaster),
        };
        let mut reader = image::ImageReader::with_format(std::io::Cursor::new(&data[..]), format);
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(self.limits.max_alloc);
        let side = u32::try_from(self.limits.max_pixels).unwrap_or(u32::MAX);
        limits.max_image_width = Some(side);
        limits.max_image_height = Some(side);
        reader.limits(limits);
        let img = reader.decode()?.into_rgba8();
        let (w, h) = img.dimensions();
        let mut px = img.into_raw();
        for p in px.chunks_exact_mut(4) {
            let a = u16::from(p[3]);
            for c in &mut p[..3] {
                *c = ((u16::from(*c) * a + 127) / 255) as u8;
            }
        }
        Ok((w, h, px))
    }
}

/// Why an image's bytes were not read or decoded; the import warning that drops the image names
/// it.
#[derive(Debug, thiserror::Error)]
pub(super) enum ImageError {
    #[error("{0}")]
    Read(#[from] std::io::Error),
    #[error("cannot inflate: {0}")]
    Inflate(std::io::Error),
    #[error("{0}")]
    Decode(#[from] image::ImageError),
    #[error("larger than {0} bytes")]
    TooLarge(u64),
    #[error("{0}")]
    Text(#[from] super::encoding::TextError),
    #[error("an SVG image is not a raster")]
    NotRaster,
}

/// The raster format of `data` by its magic bytes.
fn sniff(data: &[u8]) -> Option<image::ImageFormat> {
    use image::ImageFormat as F;
    image::guess_format(data)
        .ok()
        .filter(|f| matches!(f, F::Png | F::Jpeg | F::Gif | F::WebP))
}

/// Whether `data` reads like SVG text (or is gzip-compressed).
fn looks_like_svg(data: &[u8]) -> bool {
    data.starts_with(&[0x1f, 0x8b])
        || String::from_utf8_lossy(&data[..data.len().min(4096)]).contains("<svg")
}

/// SVG text from plain or gzip-compressed bytes, at most `max` bytes.
fn inflate(data: &[u8], max: u64) -> Result<String, ImageError> {
    use std::io::Read;
    let mut out = Vec::new();
    if data.starts_with(&[0x1f, 0x8b]) {
        flate2::read::GzDecoder::new(data)
            .take(max + 1)
            .read_to_end(&mut out)
            .map_err(ImageError::Inflate)?;
    } else {
        out.extend_from_slice(data);
    }
    if out.len() as u64 > max {
        return Err(ImageError::TooLarge(max));
    }
    Ok(super::encoding::decode(&out)?)
}

/// `href`s in warnings: a data URL or a long name cut short.
fn clip_text(s: &str) -> String {
    const MAX: usize = 60;
    match s.char_indices().nth(MAX) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s.to_string(),
    }
}
