//! CLIP byte-level BPE tokenizer, equivalent to `transformers`' `CLIPTokenizer` /
//! `CLIPTokenizerFast` (and OpenAI's and OpenCLIP's `SimpleTokenizer`).
//!
//! Text cleaning is the `ftfy`-less path shared by the fast tokenizer: Unicode NFC, runs of
//! whitespace collapsed to one space, trimmed, lowercased. (`ftfy.fix_text` additionally repairs
//! mojibake; for well-formed text, which includes every caption in the benchmark file, the
//! result is the same.) The text is split with the CLIP regex, every piece is mapped to the
//! byte-level alphabet, `</w>` marks the end of a word, and merges are applied by rank.
//!
//! Sequences are `<|startoftext|> tokens… <|endoftext|>`, truncated to the context length
//! keeping the end token, then padded with the pad token of the tokenizer config
//! (`<|endoftext|>` for OpenAI CLIP / SD 1.x, `!` (id 0) for SD 2.x).

use super::ClipError;
use regex::Regex;
use std::collections::HashMap;
use std::path::Path;
use unicode_normalization::UnicodeNormalization;

pub const BOS_TOKEN: &str = "<|startoftext|>";
pub const EOS_TOKEN: &str = "<|endoftext|>";
/// The original CLIP vocabulary caps the merges at `49152 - 256 - 2` lines.
pub const MAX_MERGES: usize = 49152 - 256 - 2;

const SPLIT_PATTERN: &str = r"(?i)<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+";

/// GPT-2 / CLIP `bytes_to_unicode`: printable bytes map to themselves, the rest to code points
/// from 256 upwards, in byte order.
pub fn bytes_to_unicode() -> [char; 256] {
    let mut printable = [false; 256];
    for b in (b'!'..=b'~').chain(0xA1..=0xAC).chain(0xAE..=0xFF) {
        printable[b as usize] = true;
    }
    let mut out = ['\0'; 256];
    let mut n = 0u32;
    for b in 0..256usize {
        out[b] = if printable[b] {
            char::from_u32(b as u32).unwrap_or('\0')
        } else {
            let c = char::from_u32(256 + n).unwrap_or('\0');
            n += 1;
            c
        };
    }
    out
}

/// Largest context length accepted from tokenizer files (guards allocations on hostile input).
pub const MAX_CONTEXT: usize = 4096;

/// A loaded CLIP tokenizer.
#[derive(Debug, Clone)]
pub struct ClipTokenizer {
    encoder: HashMap<String, u32>,
    ranks: HashMap<(String, String), usize>,
    byte_encoder: [char; 256],
    pattern: Regex,
    whitespace: Regex,
    /// `<|startoftext|>` id.
    pub bos_id: u32,
    /// `<|endoftext|>` id (also the unknown token).
    pub eos_id: u32,
    /// Padding id.
    pub pad_id: u32,
    /// Context length (`model_max_length`), 77 for every released CLIP; never above
    /// [`MAX_CONTEXT`] whatever a tokenizer file claims.
    pub max_length: usize,
}

fn token_id(encoder: &HashMap<String, u32>, tok: &str) -> Result<u32, ClipError> {
    encoder
        .get(tok)
        .copied()
        .ok_or_else(|| ClipError::Tokenizer(format!("vocabulary has no `{tok}` token")))
}

fn special_content(v: &serde_json::Value) -> Option<String> {
    match v {
        serde_json::Value::String(s) => Some(s.clone()),
        serde_json::Value::Object(m) => m.get("content").and_then(|c| c.as_str()).map(String::from),
        _ => None,
    }
}

impl ClipTokenizer {
    /// Builds a tokenizer from a vocabulary and ordered merges (highest priority first).
    pub fn new(
        encoder: HashMap<String, u32>,
        merges: Vec<(String, String)>,
    ) -> Result<Self, ClipError> {
        let bos_id = token_id(&encoder, BOS_TOKEN)?;
        let eos_id = token_id(&encoder, EOS_TOKEN)?;
        let ranks = merges
            .into_iter()
            .take(MAX_MERGES)
            .enumerate()
            .map(|(i, p)| (p, i))
            .collect();
        let pattern = Regex::new(SPLIT_PATTERN)
            .map_err(|e| ClipError::Tokenizer(format!("split pattern: {e}")))?;
        let whitespace =
            Regex::new(r"\s+").map_err(|e| ClipError::Tokenizer(format!("whitespace: {e}")))?;
        Ok(Self {
            encoder,
            ranks,
            byte_encoder: bytes_to_unicode(),
            pattern,
            whitespace,
            bos_id,
            eos_id,
            pad_id: eos_id,
            max_length: 77,
        })
    }

    /// Reads `vocab.json` and `merges.txt` (first line `#version…` skipped, as transformers does).
    pub fn from_files(vocab: &Path, merges: &Path) -> Result<Self, ClipError> {
        let text = std::fs::read_to_string(vocab).map_err(|e| ClipError::io(vocab, e))?;
        let encoder: HashMap<String, u32> = serde_json::from_str(&text)
            .map_err(|e| ClipError::Tokenizer(format!("{}: {e}", vocab.display())))?;
        let text = std::fs::read_to_string(merges).map_err(|e| ClipError::io(merges, e))?;
        let mut pairs = Vec::new();
        for (i, line) in text.trim().lines().enumerate() {
            if i == 0 && line.starts_with("#version") {
                continue;
            }
            if line.is_empty() {
                continue;
            }
            let mut it = line.split(' ');
            match (it.next(), it.next(), it.next()) {
                (Some(a), Some(b), None) => pairs.push((a.to_string(), b.to_string())),
                _ => {
                    return Err(ClipError::Tokenizer(format!(
                        "{} line {}: expected two space-separated symbols, got {line:?}",
                        merges.display(),
                        i + 1
                    )));
                }
            }
        }
        Self::new(encoder, pairs)
    }

    /// Reads a `tokenizer.json` (Hugging Face `tokenizers` format) with a BPE model.
    pub fn from_tokenizer_json(path: &Path) -> Result<Self, ClipError> {
        let err = |m: &str| ClipError::Tokenizer(format!("{}: {m}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| ClipError::io(path, e))?;
        let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| err(&e.to_string()))?;
        let model = v.get("model").ok_or_else(|| err("no `model`"))?;
        let mut encoder: HashMap<String, u32> = serde_json::from_value(
            model
                .get("vocab")
                .cloned()
                .ok_or_else(|| err("no `model.vocab`"))?,
        )
        .map_err(|e| err(&e.to_string()))?;
        if let Some(added) = v.get("added_tokens").and_then(|a| a.as_array()) {
            for t in added {
                if let (Some(c), Some(id)) = (
                    t.get("content").and_then(|c| c.as_str()),
                    t.get("id").and_then(|i| i.as_u64()),
                ) {
                    encoder.insert(c.to_string(), id as u32);
                }
            }
        }
        let merges = model
            .get("merges")
            .and_then(|m| m.as_array())
            .ok_or_else(|| err("no `model.merges`"))?;
        let mut pairs = Vec::with_capacity(merges.len());
        for m in merges {
            let pair = match m {
                serde_json::Value::String(s) => s
                    .split_once(' ')
                    .map(|(a, b)| (a.to_string(), b.to_string())),
                serde_json::Value::Array(a) if a.len() == 2 => {
                    match (a[0].as_str(), a[1].as_str()) {
                        (Some(x), Some(y)) => Some((x.to_string(), y.to_string())),
                        _ => None,
                    }
                }
                _ => None,
            };
            pairs.push(pair.ok_or_else(|| err(&format!("bad merge {m}")))?);
        }
        let mut tok = Self::new(encoder, pairs)?;
        if let Some(pad) = v
            .get("padding")
            .and_then(|p| p.get("pad_id"))
            .and_then(|p| p.as_u64())
        {
            tok.pad_id = pad as u32;
        }
        if let Some(len) = v
            .get("truncation")
            .and_then(|p| p.get("max_length"))
            .and_then(|p| p.as_u64())
        {
            tok.max_length = len as usize;
        }
        tok.max_length = tok.max_length.min(MAX_CONTEXT);
        Ok(tok)
    }

    /// Loads from a model directory (or its `tokenizer/` subfolder, the diffusers layout):
    /// `vocab.json` + `merges.txt`, else `tokenizer.json`; pad token and context length from
    /// `tokenizer_config.json` / `special_tokens_map.json` when present.
    pub fn from_dir(dir: &Path) -> Result<Self, ClipError> {
        let candidates = [dir.to_path_buf(), dir.join("tokenizer")];
        for d in &candidates {
            let (vocab, merges, json) = (
                d.join("vocab.json"),
                d.join("merges.txt"),
                d.join("tokenizer.json"),
            );
            let tok = if vocab.is_file() && merges.is_file() {
                Self::from_files(&vocab, &merges)?
            } else if json.is_file() {
                Self::from_tokenizer_json(&json)?
            } else {
                continue;
            };
            return tok.with_config_files(d);
        }
        Err(ClipError::MissingFiles {
            dir: dir.to_path_buf(),
            files: vec!["vocab.json + merges.txt, or tokenizer.json".into()],
            hint: super::DOWNLOAD_HINT.into(),
        })
    }

    fn with_config_files(mut self, dir: &Path) -> Result<Self, ClipError> {
        for name in ["special_tokens_map.json", "tokenizer_config.json"] {
            let p = dir.join(name);
            if !p.is_file() {
                continue;
            }
            let text = std::fs::read_to_string(&p).map_err(|e| ClipError::io(&p, e))?;
            let v: serde_json::Value = serde_json::from_str(&text)
                .map_err(|e| ClipError::Tokenizer(format!("{}: {e}", p.display())))?;
            if let Some(pad) = v.get("pad_token").and_then(special_content) {
                self.pad_id = token_id(&self.encoder, &pad)?;
            }
            if let Some(len) = v.get("model_max_length").and_then(|l| l.as_u64()) {
                // Tokenizers without a limit store a huge sentinel; keep the CLIP context then.
                if (2..=MAX_CONTEXT as u64).contains(&len) {
                    self.max_length = len as usize;
                }
            }
        }
        Ok(self)
    }

    /// Vocabulary size (including special tokens).
    pub fn vocab_size(&self) -> usize {
        self.encoder.len()
    }

    /// Looks a token up in the vocabulary.
    pub fn token_to_id(&self, token: &str) -> Option<u32> {
        self.encoder.get(token).copied()
    }

    /// Cleaning before the split: NFC, whitespace collapsed and trimmed, lowercase.
    pub fn normalize(&self, text: &str) -> String {
        let nfc: String = text.nfc().collect();
        self.whitespace.replace_all(&nfc, " ").trim().to_lowercase()
    }

    fn bpe(&self, word: &str, out: &mut Vec<u32>) {
        let mut parts: Vec<String> = word.chars().map(String::from).collect();
        if let Some(last) = parts.last_mut() {
            last.push_str("</w>");
        }
        loop {
            let mut best: Option<(usize, usize)> = None; // (rank, index)
            for i in 0..parts.len().saturating_sub(1) {
                let key = (parts[i].clone(), parts[i + 1].clone());
                if let Some(&r) = self.ranks.get(&key)
                    && best.is_none_or(|(br, _)| r < br)
                {
                    best = Some((r, i));
                }
            }
            let Some((_, i0)) = best else { break };
            let (first, second) = (parts[i0].clone(), parts[i0 + 1].clone());
            let mut merged = Vec::with_capacity(parts.len());
            let mut i = 0;
            while i < parts.len() {
                if i + 1 < parts.len() && parts[i] == first && parts[i + 1] == second {
                    merged.push(format!("{first}{second}"));
                    i += 2;
                } else {
                    merged.push(std::mem::take(&mut parts[i]));
                    i += 1;
                }
            }
            parts = merged;
            if parts.len() == 1 {
                break;
            }
        }
        for p in parts {
            out.push(self.encoder.get(&p).copied().unwrap_or(self.eos_id));
        }
    }

    /// Token ids of `text` without start/end tokens and without truncation.
    pub fn encode(&self, text: &str) -> Vec<u32> {
        let clean = self.normalize(text);
        let mut ids = Vec::new();
        for m in self.pattern.find_iter(&clean) {
            let piece = m.as_str();
            if piece == BOS_TOKEN {
                ids.push(self.bos_id);
                continue;
            }
            if piece == EOS_TOKEN {
                ids.push(self.eos_id);
                continue;
            }
            let word: String = piece
                .bytes()
                .map(|b| self.byte_encoder[b as usize])
                .collect();
            self.bpe(&word, &mut ids);
        }
        ids
    }

    /// `<|startoftext|> ids <|endoftext|>`, truncated to `max_length` keeping the end token
    /// (`truncation=True` in transformers), not padded.
    pub fn encode_with_special(&self, text: &str) -> Vec<u32> {
        let mut ids = self.encode(text);
        ids.truncate(self.max_length.saturating_sub(2));
        let mut out = Vec::with_capacity(ids.len() + 2);
        out.push(self.bos_id);
        out.extend(ids);
        out.push(self.eos_id);
        out
    }

    /// As [`Self::encode_with_special`], padded with the pad id to exactly `max_length`
    /// (`padding="max_length"`, as Stable Diffusion and the CLIP scorers call it).
    pub fn encode_padded(&self, text: &str) -> Vec<u32> {
        let mut ids = self.encode_with_special(text);
        ids.resize(self.max_length, self.pad_id);
        ids
    }

    /// Decodes ids back to text (byte-level inverse, `</w>` becomes a space).
    pub fn decode(&self, ids: &[u32]) -> String {
        let mut inv: HashMap<u32, &str> = HashMap::with_capacity(self.encoder.len());
        for (k, v) in &self.encoder {
            inv.insert(*v, k.as_str());
        }
        let mut byte_dec = HashMap::with_capacity(256);
        for (b, c) in self.byte_encoder.iter().enumerate() {
            byte_dec.insert(*c, b as u8);
        }
        let mut bytes = Vec::new();
        for id in ids {
            let Some(tok) = inv.get(id) else { continue };
            if *tok == BOS_TOKEN || *tok == EOS_TOKEN {
                continue;
            }
            let (body, eow) = match tok.strip_suffix("</w>") {
                Some(b) => (b, true),
                None => (*tok, false),
            };
            bytes.extend(body.chars().filter_map(|c| byte_dec.get(&c).copied()));
            if eow {
                bytes.push(b' ');
            }
        }
        String::from_utf8_lossy(&bytes).trim().to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_alphabet_is_a_bijection() {
        let m = bytes_to_unicode();
        let set: std::collections::HashSet<char> = m.iter().copied().collect();
        assert_eq!(set.len(), 256);
        assert_eq!(m[b'a' as usize], 'a');
        assert_eq!(m[b' ' as usize], '\u{120}');
    }

    fn tiny() -> ClipTokenizer {
        let alphabet = bytes_to_unicode();
        let mut vocab: Vec<String> = alphabet.iter().map(|c| c.to_string()).collect();
        vocab.extend(alphabet.iter().map(|c| format!("{c}</w>")));
        let merges = vec![
            ("c".to_string(), "a".to_string()),
            ("ca".to_string(), "t</w>".to_string()),
        ];
        for (a, b) in &merges {
            vocab.push(format!("{a}{b}"));
        }
        vocab.push(BOS_TOKEN.into());
        vocab.push(EOS_TOKEN.into());
        let enc = vocab
            .into_iter()
            .enumerate()
            .map(|(i, t)| (t, i as u32))
            .collect();
        ClipTokenizer::new(enc, merges).unwrap()
    }

    #[test]
    fn merges_apply_by_rank_and_padding_keeps_eos() {
        let mut t = tiny();
        let cat = t.token_to_id("cat</w>").unwrap();
        let ids = t.encode("  A   CAT ");
        assert_eq!(ids, vec![t.token_to_id("a</w>").unwrap(), cat]);
        assert_eq!(t.decode(&ids), "a cat");
        t.max_length = 4;
        let long = t.encode_padded("cat cat cat cat");
        assert_eq!(long, vec![t.bos_id, cat, cat, t.eos_id]);
        let short = t.encode_padded("");
        assert_eq!(short, vec![t.bos_id, t.eos_id, t.eos_id, t.eos_id]);
    }

    #[test]
    fn non_ascii_round_trips_through_bytes() {
        let t = tiny();
        let ids = t.encode("自転車");
        assert_eq!(ids.len(), 9); // 9 UTF-8 bytes, no merges in the tiny vocabulary
        assert_eq!(t.decode(&ids), "自転車");
    }
}
