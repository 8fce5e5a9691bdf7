//! The BERT WordPiece tokenizer against `transformers.BertTokenizer` on the real
//! all-MiniLM-L6-v2 vocabulary (fixture made by `scripts/embedded/make_fixtures.py`).

use std::path::{Path, PathBuf};
use vectorfusion::models::bert::BertTokenizer;

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/bert-tiny")
}

#[derive(serde::Deserialize)]
struct Case {
    text: String,
    length: usize,
    ids: Vec<u32>,
    attention_mask: Vec<u32>,
}

#[derive(serde::Deserialize)]
struct Cases {
    cases: Vec<Case>,
}

#[test]
fn ids_and_masks_match_transformers_exactly() {
    let tok = BertTokenizer::from_dir(&fixture().join("tokenizer")).unwrap();
    let s = std::fs::read_to_string(fixture().join("tokens.json")).unwrap();
    let cases: Cases = serde_json::from_str(&s).unwrap();
    assert!(cases.cases.len() >= 120, "{} cases", cases.cases.len());
    let mut bad = Vec::new();
    for c in &cases.cases {
        let e = tok.encode(&c.text, c.length).unwrap();
        if e.ids != c.ids || e.attention_mask != c.attention_mask {
            bad.push(format!(
                "{:?} (L={}):\n  got  {:?}\n  want {:?}",
                c.text, c.length, e.ids, c.ids
            ));
        }
    }
    assert!(
        bad.is_empty(),
        "{} mismatches:\n{}",
        bad.len(),
        bad.join("\n")
    );
}

#[test]
fn fixture_covers_cjk_unknowns_and_truncation() {
    let tok = BertTokenizer::from_dir(&fixture().join("tokenizer")).unwrap();
    // 自転車: one token per CJK character
    let ids = tok.tokenize_ids("自転車");
    assert_eq!(ids.len(), 3);
    // a word over 100 characters is [UNK]
    assert_eq!(tok.tokenize_ids(&"x".repeat(101)), vec![tok.unk_id]);
    // truncation keeps [SEP] last
    let e = tok.encode(&"a ".repeat(40), 32).unwrap();
    assert_eq!(e.ids[31], tok.sep_id);
    assert!(e.attention_mask.iter().all(|&m| m == 1));
    // empty caption: [CLS] [SEP] [PAD]...
    let e = tok.encode("", 32).unwrap();
    assert_eq!(&e.ids[..3], &[tok.cls_id, tok.sep_id, tok.pad_id]);
    assert_eq!(e.attention_mask.iter().sum::<u32>(), 2);
}

#[test]
fn embedded_model_tokenizer_is_the_wheel_vocab_with_length_32() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/vf-icon/tokenizer");
    let tok = BertTokenizer::from_dir(&root).unwrap();
    assert_eq!(tok.max_length, 32);
    assert_eq!(tok.vocab_size(), 30522);
    let fix = BertTokenizer::from_dir(&fixture().join("tokenizer")).unwrap();
    assert_eq!(
        tok.tokenize_ids("a red bicycle, 自転車"),
        fix.tokenize_ids("a red bicycle, 自転車")
    );
}

#[test]
fn bad_vocab_is_a_clear_error() {
    let err = BertTokenizer::from_vocab_text("a\nb\n", 32).unwrap_err();
    assert!(err.to_string().contains("[CLS]"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let err = BertTokenizer::from_dir(dir.path()).unwrap_err();
    assert!(err.to_string().contains("vocab.txt"), "{err}");
}
