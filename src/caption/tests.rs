use super::*;

fn colour(hue: Hue) -> Option<ColourName> {
    Some(ColourName { hue, shade: None })
}

fn one(caption: &str) -> CaptionObject {
    let p = parse(caption, ColourSteer::Svg).unwrap_or_else(|| panic!("{caption}: no plan"));
    assert_eq!(p.objects.len(), 1, "{caption}: {p:?}");
    p.objects[0].clone()
}

#[test]
fn colour_words_and_their_object() {
    let o = one("a blue cat");
    assert_eq!((o.words.as_str(), o.colour), ("cat", colour(Hue::Blue)));
    let o = one("A Purple Apple.");
    assert_eq!((o.words.as_str(), o.colour), ("apple", colour(Hue::Purple)));
    // Synonyms and spellings.
    assert_eq!(one("a gray elephant").colour, colour(Hue::Grey));
    assert_eq!(one("a violet car").colour, colour(Hue::Purple));
    assert_eq!(one("a navy boat").colour.map(|c| c.hue), Some(Hue::Blue));
    assert_eq!(one("a golden crown").words, "crown");
    // The first colour wins; the second is a colour too, not part of the object.
    let o = one("a red blue bird");
    assert_eq!((o.words.as_str(), o.colour), ("bird", colour(Hue::Red)));
}

#[test]
fn shades_bind_to_the_colour_after_them() {
    let o = one("a dark green car");
    assert_eq!(o.words, "car");
    assert_eq!(
        o.colour,
        Some(ColourName {
            hue: Hue::Green,
            shade: Some(Shade::Dark)
        })
    );
    let o = one("a light pink flower");
    assert_eq!(o.colour.and_then(|c| c.shade), Some(Shade::Light));
    // "light" before a thing is a word of the thing.
    assert_eq!(parse("a light bulb", ColourSteer::Svg), None);
}

#[test]
fn a_colour_word_at_the_end_is_the_thing() {
    for caption in [
        "an orange",
        "a lime",
        "an olive",
        "a crown",
        "grinning face",
    ] {
        assert_eq!(parse(caption, ColourSteer::Svg), None, "{caption}");
    }
    assert_eq!(one("an orange cat").colour, colour(Hue::Orange));
}

#[test]
fn two_objects_and_their_relation() {
    let p = parse("a cat wearing a hat", ColourSteer::Start).unwrap();
    let words: Vec<&str> = p.objects.iter().map(|o| o.words.as_str()).collect();
    assert_eq!(words, ["cat", "hat"]);
    assert_eq!(p.relation, Some(Relation::Wearing));
    assert_eq!(p.colour(), None);
    let p = parse("an astronaut riding a horse", ColourSteer::Start).unwrap();
    assert_eq!(p.relation, Some(Relation::Riding));
    assert_eq!(p.objects[1].words, "horse");
    let p = parse("a dog next to a red ball", ColourSteer::Start).unwrap();
    assert_eq!(p.relation, Some(Relation::Beside));
    assert_eq!(p.objects[1].words, "ball");
    assert_eq!(p.colour(), colour(Hue::Red));
    // The colour belongs to its object.
    let p = parse("a black cat wearing a yellow hat", ColourSteer::Start).unwrap();
    assert_eq!(p.objects[0].colour, colour(Hue::Black));
    assert_eq!(p.objects[1].colour, colour(Hue::Yellow));
    // A relation word with nothing on one side is no pair.
    assert_eq!(parse("riding a horse", ColourSteer::Start), None);
}

#[test]
fn the_plan_records_the_steering_and_reads_back() {
    let p = parse("a pink elephant", ColourSteer::Rerank).unwrap();
    assert_eq!(p.steer, ColourSteer::Rerank);
    let json = serde_json::to_string(&p).unwrap();
    assert_eq!(
        json,
        r#"{"objects":[{"words":"elephant","colour":{"hue":"pink"}}],"steer":"rerank"}"#
    );
    let back: CaptionPlan = serde_json::from_str(&json).unwrap();
    assert_eq!(back, p);
}
