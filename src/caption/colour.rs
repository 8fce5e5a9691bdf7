//! Colour names of captions and hue families of pixels: one vocabulary for both, so that "the
//! render is blue" means the same thing to the parser, the recolouring and the benchmark.

use serde::{Deserialize, Serialize};

/// A named colour (what a caption asks for) and the family a pixel falls in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Hue {
    Red,
    Orange,
    Yellow,
    Green,
    Blue,
    Purple,
    Pink,
    Brown,
    Black,
    Grey,
    White,
}

/// "dark blue", "light green": a lightness shift of the named colour.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Shade {
    Dark,
    Light,
}

/// A caption's colour: the family and an optional shade.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ColourName {
    pub hue: Hue,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shade: Option<Shade>,
}

/// Words naming a colour and the family (and shade) they mean. Words that are more often
/// things than colours ("rose", "chocolate") are left out; "orange", "lime" and "olive" count
/// only before another word ([`super::parse`]).
const WORDS: &[(&str, Hue, Option<Shade>)] = &[
    ("red", Hue::Red, None),
    ("crimson", Hue::Red, None),
    ("scarlet", Hue::Red, None),
    ("maroon", Hue::Red, Some(Shade::Dark)),
    ("orange", Hue::Orange, None),
    ("yellow", Hue::Yellow, None),
    ("golden", Hue::Yellow, None),
    ("gold", Hue::Yellow, None),
    ("green", Hue::Green, None),
    ("lime", Hue::Green, Some(Shade::Light)),
    ("olive", Hue::Green, Some(Shade::Dark)),
    ("emerald", Hue::Green, None),
    ("blue", Hue::Blue, None),
    ("navy", Hue::Blue, Some(Shade::Dark)),
    ("azure", Hue::Blue, Some(Shade::Light)),
    ("cyan", Hue::Blue, Some(Shade::Light)),
    ("turquoise", Hue::Blue, Some(Shade::Light)),
    ("teal", Hue::Blue, Some(Shade::Dark)),
    ("purple", Hue::Purple, None),
    ("violet", Hue::Purple, None),
    ("indigo", Hue::Purple, Some(Shade::Dark)),
    ("lilac", Hue::Purple, Some(Shade::Light)),
    ("lavender", Hue::Purple, Some(Shade::Light)),
    ("pink", Hue::Pink, None),
    ("magenta", Hue::Pink, None),
    ("brown", Hue::Brown, None),
    ("tan", Hue::Brown, Some(Shade::Light)),
    ("beige", Hue::Brown, Some(Shade::Light)),
    ("black", Hue::Black, None),
    ("grey", Hue::Grey, None),
    ("gray", Hue::Grey, None),
    ("silver", Hue::Grey, Some(Shade::Light)),
    ("white", Hue::White, None),
];

/// Words that shift the next colour: "dark blue", "light green".
pub(crate) fn shade_word(w: &str) -> Option<Shade> {
    match w {
        "dark" | "deep" => Some(Shade::Dark),
        "light" | "pale" | "pastel" => Some(Shade::Light),
        _ => None,
    }
}

/// The colour `w` (lower case) names, if any.
pub fn colour_word(w: &str) -> Option<ColourName> {
    WORDS
        .iter()
        .find(|(n, _, _)| *n == w)
        .map(|&(_, hue, shade)| ColourName { hue, shade })
}

impl Hue {
    pub const ALL: [Hue; 11] = [
        Hue::Red,
        Hue::Orange,
        Hue::Yellow,
        Hue::Green,
        Hue::Blue,
        Hue::Purple,
        Hue::Pink,
        Hue::Brown,
        Hue::Black,
        Hue::Grey,
        Hue::White,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            Hue::Red => "red",
            Hue::Orange => "orange",
            Hue::Yellow => "yellow",
            Hue::Green => "green",
            Hue::Blue => "blue",
            Hue::Purple => "purple",
            Hue::Pink => "pink",
            Hue::Brown => "brown",
            Hue::Black => "black",
            Hue::Grey => "grey",
            Hue::White => "white",
        }
    }

    /// Black, grey and white: no hue of their own.
    pub fn is_achromatic(self) -> bool {
        matches!(self, Hue::Black | Hue::Grey | Hue::White)
    }

    /// The hue angle (degrees) a pixel of this family is moved to; `None` for achromatic ones.
    pub fn centre(self) -> Option<f32> {
        Some(match self {
            Hue::Red => 0.0,
            Hue::Orange => 30.0,
            Hue::Yellow => 55.0,
            Hue::Green => 120.0,
            Hue::Blue => 215.0,
            Hue::Purple => 272.0,
            Hue::Pink => 325.0,
            Hue::Brown => 28.0,
            Hue::Black | Hue::Grey | Hue::White => return None,
        })
    }
}

/// Hue (degrees, 0..360), saturation and lightness (HSL) of straight RGB in `[0, 1]`.
pub fn rgb_to_hsl(r: f32, g: f32, b: f32) -> (f32, f32, f32) {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let l = (max + min) / 2.0;
    let c = max - min;
    if c <= 1e-6 {
        return (0.0, 0.0, l);
    }
    let s = c / (1.0 - (2.0 * l - 1.0).abs()).max(1e-6);
    let h = if max == r {
        60.0 * ((g - b) / c).rem_euclid(6.0)
    } else if max == g {
        60.0 * ((b - r) / c + 2.0)
    } else {
        60.0 * ((r - g) / c + 4.0)
    };
    (h.rem_euclid(360.0), s.min(1.0), l)
}

/// Straight RGB of HSL (hue in degrees).
pub fn hsl_to_rgb(h: f32, s: f32, l: f32) -> (f32, f32, f32) {
    let c = (1.0 - (2.0 * l - 1.0).abs()) * s;
    let hp = h.rem_euclid(360.0) / 60.0;
    let x = c * (1.0 - (hp.rem_euclid(2.0) - 1.0).abs());
    let (r, g, b) = match hp as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = l - c / 2.0;
    let f = |v: f32| (v + m).clamp(0.0, 1.0);
    (f(r), f(g), f(b))
}

/// The family of one straight RGB colour: white (the page), black and grey by lightness when
/// it has little chroma; else by hue, with dark oranges brown and light reds pink.
pub fn family(r: f32, g: f32, b: f32) -> Hue {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let chroma = max - min;
    if chroma < 0.12 {
        return if min > 0.88 {
            Hue::White
        } else if max < 0.22 {
            Hue::Black
        } else {
            Hue::Grey
        };
    }
    let (h, _, l) = rgb_to_hsl(r, g, b);
    let reddish = !(15.0..345.0).contains(&h);
    if (15.0..50.0).contains(&h) && max < 0.62 {
        Hue::Brown
    } else if reddish && l > 0.72 {
        Hue::Pink
    } else if reddish {
        Hue::Red
    } else if h < 45.0 {
        Hue::Orange
    } else if h < 70.0 {
        Hue::Yellow
    } else if h < 170.0 {
        Hue::Green
    } else if h < 255.0 {
        Hue::Blue
    } else if h < 290.0 {
        Hue::Purple
    } else {
        Hue::Pink
    }
}

/// Pixels per family of an image (premultiplied RGBA; drawn over white), the page (white and
/// transparent pixels) left out.
pub fn family_counts(img: &crate::image::Image) -> [usize; 11] {
    let mut counts = [0usize; 11];
    for px in img.data.chunks_exact(4) {
        let a = px[3];
        // Over white: premultiplied colour + (1 - a).
        let over = |c: f32| (c + 1.0 - a).clamp(0.0, 1.0);
        let f = family(over(px[0]), over(px[1]), over(px[2]));
        if f != Hue::White {
            counts[f as usize] += 1;
        }
    }
    counts
}

/// The largest family of an image's drawn pixels (`None`: nothing drawn); ties go to the
/// earlier family of [`Hue::ALL`].
pub fn dominant(img: &crate::image::Image) -> Option<Hue> {
    largest(&family_counts(img))
}

/// The family with the most of `counts` (`None` when all are 0).
pub fn largest(counts: &[usize; 11]) -> Option<Hue> {
    let (i, &n) = counts
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.cmp(b.1).then(b.0.cmp(&a.0)))?;
    (n > 0).then_some(Hue::ALL[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn families_of_plain_colours() {
        let cases = [
            ((0.9, 0.1, 0.1), Hue::Red),
            ((1.0, 0.55, 0.0), Hue::Orange),
            ((1.0, 0.85, 0.1), Hue::Yellow),
            ((0.2, 0.7, 0.2), Hue::Green),
            ((0.1, 0.3, 0.9), Hue::Blue),
            ((0.5, 0.2, 0.8), Hue::Purple),
            ((1.0, 0.5, 0.75), Hue::Pink),
            ((0.45, 0.27, 0.1), Hue::Brown),
            ((0.05, 0.05, 0.05), Hue::Black),
            ((0.5, 0.5, 0.5), Hue::Grey),
            ((0.98, 0.98, 0.98), Hue::White),
        ];
        for ((r, g, b), want) in cases {
            assert_eq!(family(r, g, b), want, "{r} {g} {b}");
        }
    }

    #[test]
    fn hsl_round_trips() {
        for &(r, g, b) in &[
            (0.9, 0.1, 0.1),
            (0.2, 0.6, 0.9),
            (0.3, 0.3, 0.3),
            (1.0, 0.9, 0.2),
        ] {
            let (h, s, l) = rgb_to_hsl(r, g, b);
            let (r2, g2, b2) = hsl_to_rgb(h, s, l);
            assert!(
                (r - r2).abs() + (g - g2).abs() + (b - b2).abs() < 1e-4,
                "{r} {g} {b}"
            );
        }
    }

    #[test]
    fn every_family_centre_is_its_own_family() {
        for hue in Hue::ALL.into_iter().filter(|h| !h.is_achromatic()) {
            let l = if hue == Hue::Brown { 0.3 } else { 0.5 };
            let (r, g, b) = hsl_to_rgb(hue.centre().unwrap(), 0.75, l);
            assert_eq!(family(r, g, b), hue);
        }
    }
}
