//! The image sets of an R–D run: the sub-folders of `--images` (or the PNGs in it), the ones
//! `--sets` names, `--limit` files of each spread evenly in name order.

use crate::cli::bench_vectorize::BenchVectorizeArgs;
use crate::cli::{CliError, ResultExt};
use crate::retrieval::install::comma_list;
use std::path::{Path, PathBuf};

/// The image sets of `--images`, only those of `--sets` when given; none is a usage error.
pub fn select_sets(a: &BenchVectorizeArgs) -> Result<Vec<(String, Vec<PathBuf>)>, CliError> {
    let mut sets = discover_sets(&a.images)?;
    if let Some(only) = &a.rd.sets {
        let only = comma_list(only);
        if let Some(missing) = only.iter().find(|s| !sets.iter().any(|(n, _)| n == *s)) {
            let found: Vec<&str> = sets.iter().map(|(n, _)| n.as_str()).collect();
            return Err(CliError::Usage(format!(
                "--sets: no image set {missing:?} in {} (found: {})",
                a.images.display(),
                found.join(", ")
            )));
        }
        sets.retain(|(n, _)| only.contains(n));
    }
    if sets.is_empty() {
        return Err(CliError::Usage(format!(
            "no PNG files in {} or its sub-folders (run scripts/prepare_rd_set.sh {})",
            a.images.display(),
            a.images.display()
        )));
    }
    Ok(sets)
}
/// The image sets under `dir`: `(name, PNG files in name order)`.
fn discover_sets(dir: &Path) -> Result<Vec<(String, Vec<PathBuf>)>, CliError> {
    let pngs = |d: &Path| -> Result<Vec<PathBuf>, CliError> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(d)
            .bad_input(|| format!("cannot read {}", d.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file() && p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
            .collect();
        v.sort();
        Ok(v)
    };
    let mut sets = Vec::new();
    let top = pngs(dir)?;
    if !top.is_empty() {
        let name = dir
            .file_name()
            .and_then(|s| s.to_str())
            .unwrap_or("images")
            .to_string();
        sets.push((name, top));
    }
    let mut subs: Vec<PathBuf> = std::fs::read_dir(dir)
        .bad_input(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    subs.sort();
    for sub in subs {
        let Some(name) = sub.file_name().and_then(|s| s.to_str()) else {
            continue;
        };
        if name.starts_with('_') || name.starts_with('.') {
            continue;
        }
        let files = pngs(&sub)?;
        if !files.is_empty() {
            sets.push((name.to_string(), files));
        }
    }
    Ok(sets)
}

/// `n` files evenly spaced in name order (all of them when `n` is at least their number).
pub fn spread(files: Vec<PathBuf>, n: Option<usize>) -> Vec<PathBuf> {
    match n {
        Some(n) if n < files.len() => {
            let len = files.len();
            (0..n).map(|i| files[i * len / n].clone()).collect()
        }
        _ => files,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_picks_evenly() {
        let files: Vec<PathBuf> = (0..10).map(|i| PathBuf::from(format!("{i}"))).collect();
        let got: Vec<String> = spread(files.clone(), Some(3))
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        assert_eq!(got, ["0", "3", "6"]);
        assert_eq!(spread(files.clone(), Some(20)).len(), 10);
        assert_eq!(spread(files, None).len(), 10);
    }
}
