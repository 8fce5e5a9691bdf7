//! Captions from icon names, exactly as the embedded model's training data names its icons
//! (`examples/icon_dataset.rs`, `docs/embedded/TRAINING.md`): `-`/`_` become spaces; trailing
//! variant markers (`-N`, `-flat`, `-duo`) are dropped while the name without them is also in the
//! set (`man-farmer-2`, `add-layer-2-flat`); in sets whose names have no separators at all
//! (fxemoji: `sakebottleandcup`) each name is split into the fewest whole words of a vocabulary
//! (the MiniLM `vocab.txt`).

use std::collections::HashSet;

/// Short words accepted as pieces of a split name; other pieces must have 3+ letters, so that
/// `aries` stays whole instead of becoming `ari es`.
const SHORT_WORDS: &[&str] = &[
    "a", "an", "ab", "at", "by", "cd", "do", "in", "no", "of", "ok", "on", "or", "ox", "to", "tv",
    "up", "vs",
];

/// The lower-case ASCII words of a WordPiece vocabulary (one token a line), for [`segment`].
pub fn vocab_words(vocab_txt: &str) -> HashSet<String> {
    vocab_txt
        .lines()
        .map(str::trim)
        .filter(|w| !w.is_empty() && w.chars().all(|c| c.is_ascii_lowercase()))
        .map(str::to_string)
        .collect()
}

/// Splits `s` into the fewest words from `vocab` (ties: earlier split points); `None` if
/// impossible.
pub fn segment(s: &str, vocab: &HashSet<String>) -> Option<Vec<String>> {
    let chars: Vec<char> = s.chars().collect();
    let n = chars.len();
    // best[i] = (word count, previous split) for the prefix of length i.
    let mut best: Vec<Option<(usize, usize)>> = vec![None; n + 1];
    best[0] = Some((0, 0));
    for i in 1..=n {
        for j in i.saturating_sub(20)..i {
            let Some((c, _)) = best[j] else { continue };
            let w: String = chars[j..i].iter().collect();
            let ok = vocab.contains(&w) && (w.len() > 2 || SHORT_WORDS.contains(&w.as_str()));
            if ok && best[i].is_none_or(|(b, _)| c + 1 < b) {
                best[i] = Some((c + 1, j));
            }
        }
    }
    let mut words = Vec::new();
    let mut i = n;
    while i > 0 {
        let (_, j) = best[i]?;
        words.push(chars[j..i].iter().collect());
        i = j;
    }
    words.reverse();
    Some(words)
}

/// A name ending that marks a variant of the icon named without it: `-2`, `-flat`, `-duo`.
fn is_variant_suffix(last: &str) -> bool {
    (!last.is_empty() && last.chars().all(|c| c.is_ascii_digit())) || matches!(last, "flat" | "duo")
}

/// Whether a set's names should be split into words: almost none of them has a separator.
pub fn needs_segmentation<'a>(names: impl IntoIterator<Item = &'a str>) -> bool {
    let (mut all, mut seps) = (0usize, 0usize);
    for n in names {
        all += 1;
        seps += usize::from(n.contains(['-', '_']));
    }
    seps * 20 < all
}

/// The caption of icon `name` in a set with the given `names`; `vocab` splits names without
/// separators (pass it only for sets where [`needs_segmentation`] holds).
pub fn caption(name: &str, names: &HashSet<&str>, vocab: Option<&HashSet<String>>) -> String {
    let mut base = name;
    while let Some((stem, last)) = base.rsplit_once('-')
        && is_variant_suffix(last)
        && names.contains(stem)
    {
        base = stem;
    }
    let words: Vec<String> = base
        .split(['-', '_'])
        .filter(|w| !w.is_empty())
        .flat_map(|w| match vocab.and_then(|v| segment(w, v)) {
            Some(ws) => ws,
            None => vec![w.to_string()],
        })
        .collect();
    words.join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variants_fold_into_their_base_name() {
        let names: HashSet<&str> = [
            "add-layer-2",
            "add-layer-2-flat",
            "man-farmer",
            "man-farmer-2",
            "top-10",
        ]
        .into_iter()
        .collect();
        assert_eq!(caption("add-layer-2-flat", &names, None), "add layer 2");
        assert_eq!(caption("man-farmer-2", &names, None), "man farmer");
        // no "top" icon: the number is part of the name
        assert_eq!(caption("top-10", &names, None), "top 10");
    }

    #[test]
    fn names_without_separators_split_into_the_fewest_words() {
        let vocab = vocab_words("sake\nbottle\nand\ncup\nbot\ntle\n[UNK]\n##s\n");
        assert_eq!(
            segment("sakebottleandcup", &vocab),
            Some(vec![
                "sake".into(),
                "bottle".into(),
                "and".into(),
                "cup".into()
            ])
        );
        assert_eq!(segment("xyz", &vocab), None);
        let names: HashSet<&str> = ["sakebottleandcup"].into_iter().collect();
        assert_eq!(
            caption("sakebottleandcup", &names, Some(&vocab)),
            "sake bottle and cup"
        );
        assert!(needs_segmentation(["sakebottleandcup", "cup"]));
        assert!(!needs_segmentation(["red-heart", "cup"]));
    }
}
