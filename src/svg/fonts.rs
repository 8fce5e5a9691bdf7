//! The fonts `<text>` is drawn with. usvg lays text out (shaping, `tspan`s, `textPath`,
//! spacing) and turns the glyphs into outlines, which the import keeps as paths; with no font at
//! all it drops the text, and the import says so in a warning.
//!
//! One database per process, loaded on first use ([`database`]): the font files in the
//! directories of `VF_FONT_DIRS` (separated as in `PATH`), then, unless `VF_SYSTEM_FONTS=0`,
//! the system's fonts (fontconfig's directories on Linux). The generic families (`serif`,
//! `sans-serif`, `monospace`, `cursive`, `fantasy`) name the first family of a preference list
//! ([`SERIF`], [`SANS_SERIF`], …) that the database holds, else `sans-serif`'s, else the first
//! family by name; `serif` is also usvg's fallback for a family that is not there, so any font
//! draws any text. Text depends on the fonts a machine has: the same SVG draws the same text
//! only where the same fonts are found (pin them with `VF_FONT_DIRS` and `VF_SYSTEM_FONTS=0`).

use resvg::usvg::fontdb::Database;
use std::collections::BTreeSet;
use std::ffi::OsString;
use std::sync::{Arc, OnceLock};

/// Directories of font files to load first (separated as in `PATH`).
pub const FONT_DIRS_ENV: &str = "VF_FONT_DIRS";
/// `0` leaves the system's fonts out.
pub const SYSTEM_FONTS_ENV: &str = "VF_SYSTEM_FONTS";

/// Preferred families for `serif`, first found wins.
pub const SERIF: &[&str] = &[
    "Noto Serif",
    "DejaVu Serif",
    "Liberation Serif",
    "Times New Roman",
];
/// Preferred families for `sans-serif`.
pub const SANS_SERIF: &[&str] = &["Noto Sans", "DejaVu Sans", "Liberation Sans", "Arial"];
/// Preferred families for `monospace`.
pub const MONOSPACE: &[&str] = &[
    "Noto Mono",
    "Noto Sans Mono",
    "DejaVu Sans Mono",
    "Liberation Mono",
    "Courier New",
];
/// Preferred families for `cursive`.
pub const CURSIVE: &[&str] = &["Yellowtail", "Comic Sans MS"];
/// Preferred families for `fantasy`.
pub const FANTASY: &[&str] = &["Sedgwick Ave Display", "Impact"];

/// The process's font database (see the module docs), loaded once.
pub fn database() -> Arc<Database> {
    static DB: OnceLock<Arc<Database>> = OnceLock::new();
    DB.get_or_init(|| {
        let system = std::env::var(SYSTEM_FONTS_ENV).map_or(true, |v| v.trim() != "0");
        Arc::new(load(std::env::var_os(FONT_DIRS_ENV), system))
    })
    .clone()
}

/// A database of the fonts in `dirs` (separated as in `PATH`) and, with `system`, the system's,
/// its generic families set (see the module docs).
pub fn load(dirs: Option<OsString>, system: bool) -> Database {
    let mut db = Database::new();
    if let Some(dirs) = dirs {
        for dir in std::env::split_paths(&dirs) {
            db.load_fonts_dir(dir);
        }
    }
    if system {
        db.load_system_fonts();
    }
    set_generic_families(&mut db);
    db
}

/// Points the generic families at families the database holds.
fn set_generic_families(db: &mut Database) {
    let have: BTreeSet<String> = db
        .faces()
        .flat_map(|f| f.families.iter().map(|(name, _)| name.clone()))
        .collect();
    let Some(first) = have.iter().next().cloned() else {
        return;
    };
    let pick = |list: &[&str]| {
        list.iter()
            .find(|n| have.contains(**n))
            .map(|n| n.to_string())
    };
    let sans = pick(SANS_SERIF).unwrap_or(first);
    let or_sans = |list: &[&str]| pick(list).unwrap_or_else(|| sans.clone());
    db.set_serif_family(or_sans(SERIF));
    db.set_monospace_family(or_sans(MONOSPACE));
    db.set_cursive_family(or_sans(CURSIVE));
    db.set_fantasy_family(or_sans(FANTASY));
    db.set_sans_serif_family(sans);
}

#[cfg(test)]
mod tests {
    use super::*;
    use resvg::usvg::fontdb::{Family, Query};

    #[test]
    fn no_fonts_no_faces_and_a_missing_directory_is_no_error() {
        let db = load(Some("/nonexistent-vf-fonts".into()), false);
        assert!(db.is_empty());
        let q = Query {
            families: &[Family::Serif],
            ..Query::default()
        };
        assert!(db.query(&q).is_none());
    }
}
