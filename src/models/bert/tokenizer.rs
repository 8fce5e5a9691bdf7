//! BERT uncased WordPiece tokenizer, equivalent to `transformers.BertTokenizer` (the
//! `tokenizers`-backed one of transformers 5: `BertNormalizer` + `BertPreTokenizer` + `WordPiece`
//! + `[CLS] $A [SEP]` template) on a `vocab.txt`.
//!
//! Normalisation, in the order `tokenizers` applies it:
//! 1. clean: drop NUL, U+FFFD and control/format/private-use characters (general categories
//!    Cc, Cf, Co, except `\t \n \r`); every whitespace character becomes a space;
//! 2. CJK ideographs (the BERT code point blocks) get a space on each side;
//! 3. strip accents: NFD, then drop non-spacing marks (Mn);
//! 4. lower case, character by character (so no final-sigma rule).
//!
//! Pre-tokenisation splits on whitespace and isolates every punctuation character (ASCII
//! punctuation and Unicode category P). WordPiece is greedy longest-match-first with `##`
//! continuations; a word with more than 100 characters or without a full match is `[UNK]`.

use super::BertError;
use regex::Regex;
use std::collections::HashMap;
use std::path::Path;
use std::sync::LazyLock;
use unicode_normalization::UnicodeNormalization;

pub const CLS_TOKEN: &str = "[CLS]";
pub const SEP_TOKEN: &str = "[SEP]";
pub const PAD_TOKEN: &str = "[PAD]";
pub const UNK_TOKEN: &str = "[UNK]";
/// Words longer than this (in characters) are `[UNK]`.
pub const MAX_INPUT_CHARS_PER_WORD: usize = 100;
/// Largest sequence length accepted (BERT's position table has 512 entries).
pub const MAX_LENGTH: usize = 512;

static CONTROL: LazyLock<Option<Regex>> =
    LazyLock::new(|| Regex::new(r"^[\p{Cc}\p{Cf}\p{Co}]$").ok());
static PUNCT: LazyLock<Option<Regex>> = LazyLock::new(|| Regex::new(r"^\p{P}$").ok());
static NONSPACING_MARK: LazyLock<Option<Regex>> = LazyLock::new(|| Regex::new(r"^\p{Mn}$").ok());

fn char_is(re: &LazyLock<Option<Regex>>, c: char) -> bool {
    let mut buf = [0u8; 4];
    re.as_ref()
        .is_some_and(|r| r.is_match(c.encode_utf8(&mut buf)))
}

fn is_control(c: char) -> bool {
    !matches!(c, '\t' | '\n' | '\r') && char_is(&CONTROL, c)
}

fn is_whitespace(c: char) -> bool {
    matches!(c, '\t' | '\n' | '\r') || c.is_whitespace()
}

fn is_punctuation(c: char) -> bool {
    c.is_ascii_punctuation() || char_is(&PUNCT, c)
}

/// The CJK blocks BERT splits into single characters (as `tokenizers` spells them).
fn is_chinese_char(c: char) -> bool {
    matches!(c as u32,
        0x4E00..=0x9FFF
        | 0x3400..=0x4DBF
        | 0x20000..=0x2A6DF
        | 0x2A700..=0x2B73F
        | 0x2B740..=0x2B81F
        | 0x2B920..=0x2CEAF
        | 0xF900..=0xFAFF
        | 0x2F800..=0x2FA1F)
}

/// Token ids and attention mask of one text, padded to a fixed length.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Encoding {
    pub ids: Vec<u32>,
    /// 1 on real tokens (including `[CLS]`/`[SEP]`), 0 on padding.
    pub attention_mask: Vec<u32>,
}

/// A loaded BERT WordPiece tokenizer.
#[derive(Debug, Clone)]
pub struct BertTokenizer {
    vocab: HashMap<String, u32>,
    pub do_lower_case: bool,
    /// Default sequence length (`model_max_length` of `tokenizer_config.json`, capped at 512).
    pub max_length: usize,
    pub cls_id: u32,
    pub sep_id: u32,
    pub pad_id: u32,
    pub unk_id: u32,
}

impl BertTokenizer {
    /// Builds a tokenizer from the lines of a `vocab.txt` (line `i` is token id `i`).
    pub fn from_vocab_text(text: &str, max_length: usize) -> Result<Self, BertError> {
        let mut vocab = HashMap::new();
        for (i, line) in text.lines().enumerate() {
            let tok = line.strip_suffix('\r').unwrap_or(line);
            let id = u32::try_from(i)
                .map_err(|_| BertError::Tokenizer("vocab.txt has too many lines".into()))?;
            // like `load_vocab`, a repeated token keeps the later id
            vocab.insert(tok.to_string(), id);
        }
        let id = |t: &str| {
            vocab
                .get(t)
                .copied()
                .ok_or_else(|| BertError::Tokenizer(format!("vocab.txt has no {t} token")))
        };
        if !(2..=MAX_LENGTH).contains(&max_length) {
            return Err(BertError::Tokenizer(format!(
                "max length {max_length} outside 2..={MAX_LENGTH}"
            )));
        }
        Ok(Self {
            cls_id: id(CLS_TOKEN)?,
            sep_id: id(SEP_TOKEN)?,
            pad_id: id(PAD_TOKEN)?,
            unk_id: id(UNK_TOKEN)?,
            vocab,
            do_lower_case: true,
            max_length,
        })
    }

    /// Loads `dir/vocab.txt` and, when present, `dir/tokenizer_config.json` (`do_lower_case`,
    /// `model_max_length`; a length above 512 or absent means 512).
    pub fn from_dir(dir: &Path) -> Result<Self, BertError> {
        let vp = dir.join("vocab.txt");
        let text = std::fs::read_to_string(&vp).map_err(|e| BertError::io(&vp, e))?;
        let cp = dir.join("tokenizer_config.json");
        let mut max_length = MAX_LENGTH;
        let mut lower = true;
        if cp.is_file() {
            let s = std::fs::read_to_string(&cp).map_err(|e| BertError::io(&cp, e))?;
            let v: serde_json::Value = serde_json::from_str(&s).map_err(|e| BertError::Config {
                path: cp.display().to_string(),
                reason: e.to_string(),
            })?;
            if let Some(n) = v.get("model_max_length").and_then(|x| x.as_f64())
                && n >= 2.0
                && n < MAX_LENGTH as f64
            {
                max_length = n as usize;
            }
            if let Some(b) = v.get("do_lower_case").and_then(|x| x.as_bool()) {
                lower = b;
            }
        }
        let mut t = Self::from_vocab_text(&text, max_length)?;
        t.do_lower_case = lower;
        Ok(t)
    }

    pub fn vocab_size(&self) -> usize {
        self.vocab.len()
    }

    /// The id of a vocabulary token.
    pub fn token_id(&self, token: &str) -> Option<u32> {
        self.vocab.get(token).copied()
    }

    /// Normalised text (cleaning, CJK spacing, and for uncased models accent stripping and
    /// lower casing).
    pub fn normalize(&self, text: &str) -> String {
        let mut s = String::with_capacity(text.len());
        for c in text.chars() {
            if c == '\0' || c == '\u{fffd}' || is_control(c) {
                continue;
            }
            if is_whitespace(c) {
                s.push(' ');
            } else if is_chinese_char(c) {
                s.push(' ');
                s.push(c);
                s.push(' ');
            } else {
                s.push(c);
            }
        }
        if !self.do_lower_case {
            return s;
        }
        s.nfd()
            .filter(|&c| !char_is(&NONSPACING_MARK, c))
            .flat_map(char::to_lowercase)
            .collect()
    }

    /// Words after whitespace and punctuation splitting of normalised text.
    fn pre_tokenize(text: &str) -> Vec<&str> {
        let mut out = Vec::new();
        for word in text.split(is_whitespace).filter(|w| !w.is_empty()) {
            let mut start = 0;
            for (i, c) in word.char_indices() {
                if is_punctuation(c) {
                    if start < i {
                        out.push(&word[start..i]);
                    }
                    out.push(&word[i..i + c.len_utf8()]);
                    start = i + c.len_utf8();
                }
            }
            if start < word.len() {
                out.push(&word[start..]);
            }
        }
        out
    }

    /// Greedy longest-match-first WordPiece of one word; `[UNK]` when it cannot be covered.
    fn wordpiece(&self, word: &str, out: &mut Vec<u32>) {
        if word.chars().count() > MAX_INPUT_CHARS_PER_WORD {
            out.push(self.unk_id);
            return;
        }
        let first = out.len();
        let mut start = 0;
        let mut piece = String::new();
        while start < word.len() {
            let mut end = word.len();
            let mut found = None;
            while start < end {
                piece.clear();
                if start > 0 {
                    piece.push_str("##");
                }
                piece.push_str(&word[start..end]);
                if let Some(&id) = self.vocab.get(piece.as_str()) {
                    found = Some(id);
                    break;
                }
                end -= word[..end].chars().next_back().map_or(1, char::len_utf8);
            }
            match found {
                Some(id) => out.push(id),
                None => {
                    out.truncate(first);
                    out.push(self.unk_id);
                    return;
                }
            }
            start = end;
        }
    }

    /// WordPiece ids of a text, without special tokens.
    pub fn tokenize_ids(&self, text: &str) -> Vec<u32> {
        let norm = self.normalize(text);
        let mut ids = Vec::new();
        for w in Self::pre_tokenize(&norm) {
            self.wordpiece(w, &mut ids);
        }
        ids
    }

    /// `[CLS] pieces[..len-2] [SEP]` padded with `[PAD]` to `len`, and the attention mask.
    pub fn encode(&self, text: &str, len: usize) -> Result<Encoding, BertError> {
        if !(2..=MAX_LENGTH).contains(&len) {
            return Err(BertError::Input(format!(
                "sequence length {len} outside 2..={MAX_LENGTH}"
            )));
        }
        let pieces = self.tokenize_ids(text);
        let n = pieces.len().min(len - 2);
        let mut ids = Vec::with_capacity(len);
        ids.push(self.cls_id);
        ids.extend_from_slice(&pieces[..n]);
        ids.push(self.sep_id);
        let mut attention_mask = vec![1u32; ids.len()];
        ids.resize(len, self.pad_id);
        attention_mask.resize(len, 0);
        Ok(Encoding {
            ids,
            attention_mask,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny() -> BertTokenizer {
        let vocab = "[PAD]\n[UNK]\n[CLS]\n[SEP]\nun\n##aff\n##able\n,\nhello\na\n##b\n";
        BertTokenizer::from_vocab_text(vocab, 16).unwrap()
    }

    #[test]
    fn category_patterns_compile() {
        assert!(CONTROL.is_some() && PUNCT.is_some() && NONSPACING_MARK.is_some());
        assert!(is_control('\u{200b}') && is_control('\u{7f}') && !is_control('\n'));
        assert!(is_punctuation('、') && is_punctuation('$') && !is_punctuation('a'));
    }

    #[test]
    fn wordpiece_is_greedy_and_all_or_nothing() {
        let t = tiny();
        assert_eq!(t.tokenize_ids("unaffable"), vec![4, 5, 6]);
        assert_eq!(t.tokenize_ids("Hello,unaffablex"), vec![8, 7, 1]);
        assert_eq!(t.tokenize_ids("ab"), vec![9, 10]);
        assert_eq!(t.tokenize_ids(&"a".repeat(101)), vec![1]);
    }

    #[test]
    fn encode_pads_and_truncates() {
        let t = tiny();
        let e = t.encode("hello", 5).unwrap();
        assert_eq!(e.ids, vec![2, 8, 3, 0, 0]);
        assert_eq!(e.attention_mask, vec![1, 1, 1, 0, 0]);
        let e = t.encode("hello , hello , hello", 4).unwrap();
        assert_eq!(e.ids, vec![2, 8, 7, 3]);
        assert!(t.encode("x", 1).is_err());
    }

    #[test]
    fn normalisation_strips_accents_then_lowercases() {
        let t = tiny();
        assert_eq!(t.normalize("Héllo\tİ\u{200d}x"), "hello ix");
        assert_eq!(t.normalize("自転"), " 自  転 ");
        assert_eq!(t.normalize("ΟΔΟΣ"), "οδοσ");
    }
}
