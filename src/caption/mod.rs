//! What a caption asks for beyond its words' embedding: the colour it names and the objects it
//! names, parsed once into the run plan ([`CaptionPlan`]) so that a small prior that does not
//! bind colour words or draw two things can be steered toward them (retrieval for the object,
//! recolouring, a colour-first rerank, a composed start: [`crate::stages::steer`]).
//!
//! | file | what |
//! |---|---|
//! | [`colour`] | colour words, hue families of pixels, the dominant family of a picture |
//! | [`recolour`] | a picture or a scene moved into a named colour's family |
//! | [`compose`] | two pictures laid out as a relation says ("wearing", "riding", "beside") |

pub mod colour;
pub mod compose;
pub mod recolour;

pub use colour::{ColourName, Hue, Shade};
use serde::{Deserialize, Serialize};

/// How two named objects stand to each other, as far as a layout needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Relation {
    /// "a cat wearing a hat": the second on top of the first.
    Wearing,
    /// "an astronaut riding a horse", "a cat on a box": the first above the second.
    Riding,
    /// "a cat and a dog", "a bear holding a balloon", "a fox with an umbrella": side by side.
    Beside,
}

/// Words that join two objects, and the relation they mean ("next to" is matched as "next").
const RELATIONS: &[(&str, Relation)] = &[
    ("wearing", Relation::Wearing),
    ("riding", Relation::Riding),
    ("on", Relation::Riding),
    ("holding", Relation::Beside),
    ("with", Relation::Beside),
    ("and", Relation::Beside),
    ("beside", Relation::Beside),
    ("next", Relation::Beside),
];

/// Words left out of an object's name.
const FILLER: &[&str] = &["a", "an", "the", "some", "to", "of"];

/// One thing a caption names: its words (without articles and colour) and its colour.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaptionObject {
    pub words: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<ColourName>,
}

/// How far the sampler steers a small prior toward a caption's colour (the model's
/// `_colour_steer` hint; each level includes the ones before it). Stable Diffusion reads colour
/// words itself and is left alone (`off`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ColourSteer {
    #[default]
    Off,
    /// Retrieve for the object's words, recolour the retrieved starts, compose two objects.
    Start,
    /// Also rank samples of the caption's colour family first.
    Rerank,
    /// Also recolour the kept sample before it is traced.
    Sample,
    /// Also recolour the final SVG's fills of its largest family.
    Svg,
}

/// A caption's colour and objects as the run plan keeps them, with the steering the model asks
/// for. Only captions that name a colour or more than one thing have one.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaptionPlan {
    /// One or two objects; the colour is each object's.
    pub objects: Vec<CaptionObject>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relation: Option<Relation>,
    #[serde(default)]
    pub steer: ColourSteer,
}

impl CaptionPlan {
    /// The colour the picture as a whole should have: the first object's, else the second's.
    pub fn colour(&self) -> Option<ColourName> {
        self.objects.iter().find_map(|o| o.colour)
    }

    /// Whether the caption names two things.
    pub fn is_pair(&self) -> bool {
        self.objects.len() > 1
    }
}

/// Lower-case words of `caption` (letters, digits, hyphen and apostrophe kept; "blue-green"
/// is two words).
fn words(caption: &str) -> Vec<String> {
    caption
        .to_lowercase()
        .split(|c: char| !(c.is_alphanumeric() || c == '\''))
        .filter(|w| !w.is_empty())
        .map(str::to_string)
        .collect()
}

/// One object of a phrase's words: a colour word counts when another word follows it (so "an
/// orange" is the fruit, "an orange cat" a colour), with "dark"/"light" before it; the first
/// colour wins. `None` when nothing but filler is left.
fn object(phrase: &[String]) -> Option<CaptionObject> {
    let mut colour = None;
    let mut kept: Vec<&str> = Vec::new();
    let mut shade = None;
    for (i, w) in phrase.iter().enumerate() {
        let followed = phrase[i + 1..]
            .iter()
            .any(|n| !FILLER.contains(&n.as_str()));
        if let Some(s) = colour::shade_word(w).filter(|_| followed) {
            let next_is_colour = phrase
                .get(i + 1)
                .is_some_and(|n| colour::colour_word(n).is_some());
            if next_is_colour {
                shade = Some(s);
                continue;
            }
        }
        match colour::colour_word(w).filter(|_| followed) {
            Some(c) if colour.is_none() => {
                colour = Some(ColourName {
                    shade: shade.or(c.shade),
                    ..c
                })
            }
            Some(_) => {}
            None if FILLER.contains(&w.as_str()) => {}
            None => kept.push(w),
        }
    }
    (!kept.is_empty()).then(|| CaptionObject {
        words: kept.join(" "),
        colour,
    })
}

/// The colour and objects `caption` names, with the steering `steer`; `None` for a caption of
/// one uncoloured thing (the run is then exactly what it was without this parse).
pub fn parse(caption: &str, steer: ColourSteer) -> Option<CaptionPlan> {
    let ws = words(caption);
    let split = ws.iter().enumerate().skip(1).find_map(|(i, w)| {
        RELATIONS
            .iter()
            .find(|(r, _)| r == w)
            .map(|&(_, rel)| (i, rel))
    });
    let (objects, relation) = match split {
        Some((i, rel)) => {
            let skip = usize::from(ws[i] == "next" && ws.get(i + 1).is_some_and(|w| w == "to"));
            let parts = [object(&ws[..i]), object(&ws[i + 1 + skip..])];
            match parts {
                [Some(a), Some(b)] => (vec![a, b], Some(rel)),
                [Some(a), None] | [None, Some(a)] => (vec![a], None),
                [None, None] => (Vec::new(), None),
            }
        }
        None => (object(&ws).into_iter().collect(), None),
    };
    let plan = CaptionPlan {
        objects,
        relation,
        steer,
    };
    (plan.is_pair() || plan.colour().is_some()).then_some(plan)
}

#[cfg(test)]
mod tests;
