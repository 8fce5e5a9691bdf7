//! Colour binding: for captions that name a colour ("a blue cat"), the share of pictures whose
//! largest hue family among their drawn pixels ([`crate::caption::colour::dominant`]; white
//! counts as the page) is the caption's colour. The benchmark list is
//! `docs/embedded/colour60.txt` (`docs/embedded/COLOUR.md`).

use crate::caption::colour::dominant;
use crate::caption::{ColourSteer, Hue, parse};
use crate::image::Image;
use serde::Serialize;

/// One coloured caption's picture.
#[derive(Debug, Clone, Serialize)]
pub struct ColourRow {
    /// 1-based caption line.
    pub line: usize,
    pub asked: Hue,
    /// The picture's largest family (`None`: nothing drawn).
    pub got: Option<Hue>,
}

/// Colour binding over the captions that name a colour.
#[derive(Debug, Clone, Serialize)]
pub struct ColourBinding {
    /// Captions that name a colour (one object's).
    pub captions: usize,
    /// Pictures whose largest family is that colour.
    pub bound: usize,
    /// `bound / captions`, in [0, 1].
    pub rate: f64,
    pub rows: Vec<ColourRow>,
}

impl std::fmt::Display for ColourBinding {
    /// `bound/captions (rate %)`, as the tables print it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}/{} ({:.1}%)",
            self.bound,
            self.captions,
            100.0 * self.rate
        )
    }
}

/// Colour binding of `images[i]` (drawn for `captions[i]`); `None` when no caption names a
/// colour.
pub fn colour_binding(captions: &[String], images: &[Image]) -> Option<ColourBinding> {
    let rows: Vec<ColourRow> = captions
        .iter()
        .zip(images)
        .enumerate()
        .filter_map(|(i, (c, img))| {
            let asked = parse(c, ColourSteer::Off)?.colour()?.hue;
            Some(ColourRow {
                line: i + 1,
                asked,
                got: dominant(img),
            })
        })
        .collect();
    if rows.is_empty() {
        return None;
    }
    let bound = rows.iter().filter(|r| r.got == Some(r.asked)).count();
    Some(ColourBinding {
        captions: rows.len(),
        bound,
        rate: bound as f64 / rows.len() as f64,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn filled(rgb: [f32; 3]) -> Image {
        let mut img = Image::new(4, 4);
        for px in img.data.chunks_exact_mut(4) {
            px.copy_from_slice(&[rgb[0], rgb[1], rgb[2], 1.0]);
        }
        img
    }

    #[test]
    fn counts_pictures_of_the_named_colour() {
        let captions = ["a blue cat", "a red car", "a crown"].map(String::from);
        let images = [
            filled([0.1, 0.2, 0.9]),
            filled([0.1, 0.8, 0.1]),
            filled([1.0, 0.9, 0.1]),
        ];
        let b = colour_binding(&captions, &images).unwrap();
        assert_eq!((b.captions, b.bound), (2, 1));
        assert_eq!(b.rows[1].got, Some(Hue::Green));
        assert_eq!(b.to_string(), "1/2 (50.0%)");
        assert!(colour_binding(&captions[2..], &images[2..]).is_none());
    }
}
