//! SVG bytes to text: UTF-8 (with or without a byte-order mark), UTF-16 by its byte-order mark,
//! and the legacy encodings an XML declaration names (`encoding="windows-1251"`,
//! `"iso-8859-1"` — old Illustrator files), labelled as the WHATWG Encoding Standard labels
//! them. Bytes that are not valid in the encoding they claim are an error, never replaced.

use encoding_rs::{Encoding, UTF_8, UTF_16BE, UTF_16LE};

/// Why bytes are not SVG text.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TextError {
    #[error("not valid UTF-8, and no XML declaration names another encoding")]
    NotUtf8,
    #[error("the XML declaration names an unknown encoding {0:?}")]
    UnknownEncoding(String),
    #[error("not valid {0} text")]
    Malformed(&'static str),
}

/// Decodes SVG file bytes to text (see the module docs).
pub fn decode(bytes: &[u8]) -> Result<String, TextError> {
    if let Some((enc, bom)) = Encoding::for_bom(bytes) {
        return strict(enc, &bytes[bom..]);
    }
    if let Ok(s) = std::str::from_utf8(bytes) {
        return Ok(s.to_owned());
    }
    let label = declared_encoding(bytes).ok_or(TextError::NotUtf8)?;
    let enc = Encoding::for_label(label.as_bytes())
        .ok_or_else(|| TextError::UnknownEncoding(label.clone()))?;
    // A UTF-16 label without a byte-order mark cannot be what the ASCII declaration was read
    // from; UTF-8 was tried above.
    if enc == UTF_16LE || enc == UTF_16BE || enc == UTF_8 {
        return Err(TextError::Malformed(enc.name()));
    }
    strict(enc, bytes)
}

fn strict(enc: &'static Encoding, bytes: &[u8]) -> Result<String, TextError> {
    enc.decode_without_bom_handling_and_without_replacement(bytes)
        .map(|s| s.into_owned())
        .ok_or(TextError::Malformed(enc.name()))
}

/// The `encoding` of an XML declaration at the very start of `bytes` (ASCII-compatible
/// encodings only).
fn declared_encoding(bytes: &[u8]) -> Option<String> {
    let head = &bytes[..bytes.len().min(256)];
    if !head.starts_with(b"<?xml") {
        return None;
    }
    let end = head.windows(2).position(|w| w == b"?>")?;
    let decl = std::str::from_utf8(&head[..end]).ok()?;
    let at = decl.find("encoding")? + "encoding".len();
    let rest = decl[at..].trim_start().strip_prefix('=')?.trim_start();
    let quote = rest.chars().next().filter(|c| *c == '"' || *c == '\'')?;
    let value = &rest[1..];
    let close = value.find(quote)?;
    Some(value[..close].trim().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utf8_with_and_without_a_byte_order_mark() {
        assert_eq!(decode("<svg>é</svg>".as_bytes()).unwrap(), "<svg>é</svg>");
        let mut bom = vec![0xEF, 0xBB, 0xBF];
        bom.extend_from_slice("<svg>é</svg>".as_bytes());
        assert_eq!(decode(&bom).unwrap(), "<svg>é</svg>");
    }

    #[test]
    fn utf16_by_its_byte_order_mark() {
        let mut le = vec![0xFF, 0xFE];
        for u in "<svg>Ж</svg>".encode_utf16() {
            le.extend_from_slice(&u.to_le_bytes());
        }
        assert_eq!(decode(&le).unwrap(), "<svg>Ж</svg>");
    }

    #[test]
    fn a_declared_legacy_encoding_is_decoded() {
        // "Привет" in windows-1251, "café" in ISO-8859-1 (windows-1252 as WHATWG maps it).
        let mut cyr = b"<?xml version=\"1.0\" encoding=\"Windows-1251\"?><svg><text>".to_vec();
        cyr.extend_from_slice(&[0xCF, 0xF0, 0xE8, 0xE2, 0xE5, 0xF2]);
        cyr.extend_from_slice(b"</text></svg>");
        assert!(decode(&cyr).unwrap().contains("<text>Привет</text>"));
        let mut latin = b"<?xml version='1.0' encoding = 'iso-8859-1' ?><svg>caf".to_vec();
        latin.extend_from_slice(&[0xE9]);
        latin.extend_from_slice(b"</svg>");
        assert!(decode(&latin).unwrap().ends_with("<svg>café</svg>"));
    }

    #[test]
    fn undeclared_or_unknown_encodings_are_errors() {
        let bad = [b'<', b's', b'v', b'g', b'>', 0xE9, b'<'];
        assert_eq!(decode(&bad), Err(TextError::NotUtf8));
        let mut unknown = b"<?xml version=\"1.0\" encoding=\"klingon\"?><svg>".to_vec();
        unknown.push(0xE9);
        assert_eq!(
            decode(&unknown),
            Err(TextError::UnknownEncoding("klingon".into()))
        );
        // Declared UTF-8 yet invalid: an error, not replacement characters.
        let mut lying = b"<?xml version=\"1.0\" encoding=\"UTF-8\"?><svg>".to_vec();
        lying.push(0xE9);
        assert_eq!(decode(&lying), Err(TextError::Malformed("UTF-8")));
    }
}
