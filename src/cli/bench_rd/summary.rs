//! The rate–distortion summary: means per tool and setting, each tool's envelope (its upper
//! Pareto frontier of mean KB against mean PSNR) and `live − peer` between envelopes, printed
//! as tables.

use super::{EditCounts, RdSample};
use serde::Serialize;

/// Means of one tool and setting over one set's images.
#[derive(Clone, Debug, Serialize)]
pub struct RdMean {
    pub set: String,
    pub tool: String,
    pub setting: String,
    pub images: usize,
    pub paths: f64,
    pub psnr: f64,
    pub ssim: f64,
    pub svg_bytes: f64,
    pub svg_gz_bytes: f64,
    pub seconds: f64,
    /// Means of the editability counts over the images that have them.
    pub self_intersecting: Option<f64>,
    pub hidden: Option<f64>,
    pub slivers: Option<f64>,
    pub colors: Option<f64>,
}

/// One tool's envelope on one set and basis: `(KB, PSNR)` points, KB ascending.
#[derive(Clone, Debug, Serialize)]
pub struct Envelope {
    pub tool: String,
    pub points: Vec<(f64, f64)>,
    /// The setting of each point.
    pub settings: Vec<String>,
}

/// `live − peer` at one size.
#[derive(Clone, Debug, Serialize)]
pub struct Delta {
    pub peer: String,
    pub kb: f64,
    pub live: Option<f64>,
    pub peer_psnr: Option<f64>,
    pub delta_db: Option<f64>,
    /// `kb` lies past the largest point of either envelope (read flat there).
    pub beyond: bool,
}

/// The R–D summary of one set on one basis.
#[derive(Clone, Debug, Serialize)]
pub struct RdSummary {
    pub set: String,
    /// `raw` or `gzip`.
    pub basis: String,
    pub envelopes: Vec<Envelope>,
    pub deltas: Vec<Delta>,
}

/// Means per (set, tool, setting), in first-seen order.
pub fn means(samples: &[RdSample]) -> Vec<RdMean> {
    let mut keys: Vec<(&str, &str, &str)> = Vec::new();
    for s in samples {
        let k = (s.set.as_str(), s.tool.as_str(), s.setting.as_str());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(set, tool, setting)| {
            let g: Vec<&RdSample> = samples
                .iter()
                .filter(|s| s.set == set && s.tool == tool && s.setting == setting)
                .collect();
            let n = g.len().max(1) as f64;
            let mean = |f: &dyn Fn(&RdSample) -> f64| g.iter().map(|s| f(s)).sum::<f64>() / n;
            let edits: Vec<EditCounts> = g.iter().filter_map(|s| s.editability).collect();
            let emean = |f: &dyn Fn(&EditCounts) -> usize| {
                (!edits.is_empty())
                    .then(|| edits.iter().map(|e| f(e) as f64).sum::<f64>() / edits.len() as f64)
            };
            RdMean {
                set: set.to_string(),
                tool: tool.to_string(),
                setting: setting.to_string(),
                images: g.len(),
                paths: mean(&|s| s.paths as f64),
                // Identical renders (infinite PSNR) count as 100 dB.
                psnr: mean(&|s| s.psnr.min(100.0)),
                ssim: mean(&|s| s.ssim),
                svg_bytes: mean(&|s| s.svg_bytes as f64),
                svg_gz_bytes: mean(&|s| s.svg_gz_bytes as f64),
                seconds: mean(&|s| s.seconds),
                self_intersecting: emean(&|e| e.self_intersecting),
                hidden: emean(&|e| e.hidden),
                slivers: emean(&|e| e.slivers),
                colors: emean(&|e| e.colors),
            }
        })
        .collect()
}

/// The upper Pareto frontier of `(x, y)` points: x ascending, y strictly increasing.
pub fn envelope(pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    envelope_indices(&pts).into_iter().map(|i| pts[i]).collect()
}

/// Indices of the points of [`envelope`], in its order.
fn envelope_indices(pts: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len())
        .filter(|&i| pts[i].0.is_finite() && pts[i].1.is_finite())
        .collect();
    // By x, and at equal x the best y first.
    idx.sort_by(|&a, &b| {
        pts[a]
            .0
            .total_cmp(&pts[b].0)
            .then(pts[b].1.total_cmp(&pts[a].1))
    });
    let mut out: Vec<usize> = Vec::new();
    for i in idx {
        if out.last().is_none_or(|&l| pts[i].1 > pts[l].1) {
            out.push(i);
        }
    }
    out
}

/// The envelope at `x`: linear between its points, its best value after the last, `None`
/// before the first.
pub fn envelope_at(env: &[(f64, f64)], x: f64) -> Option<f64> {
    let first = env.first()?;
    if x < first.0 {
        return None;
    }
    for w in env.windows(2) {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        if x <= x1 {
            return Some(if x1 > x0 {
                y0 + (y1 - y0) * (x - x0) / (x1 - x0)
            } else {
                y1
            });
        }
    }
    env.last().map(|p| p.1)
}

/// Envelopes of every tool on one set and basis, and `live − peer` at each size.
pub fn summarise_set(means: &[RdMean], set: &str, basis: &str, kbs: &[f64]) -> RdSummary {
    let mut tools: Vec<&str> = Vec::new();
    for m in means.iter().filter(|m| m.set == set) {
        if !tools.contains(&m.tool.as_str()) {
            tools.push(&m.tool);
        }
    }
    let envelopes: Vec<Envelope> = tools
        .iter()
        .map(|&tool| {
            let rows: Vec<&RdMean> = means
                .iter()
                .filter(|m| m.set == set && m.tool == tool)
                .collect();
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .map(|m| {
                    let bytes = if basis == "gzip" {
                        m.svg_gz_bytes
                    } else {
                        m.svg_bytes
                    };
                    (bytes / 1000.0, m.psnr)
                })
                .collect();
            let idx = envelope_indices(&pts);
            Envelope {
                tool: tool.to_string(),
                points: idx.iter().map(|&i| pts[i]).collect(),
                settings: idx.iter().map(|&i| rows[i].setting.clone()).collect(),
            }
        })
        .collect();
    let live = envelopes.iter().find(|e| e.tool == "live");
    let mut deltas = Vec::new();
    if let Some(live) = live {
        for peer in envelopes.iter().filter(|e| e.tool != "live") {
            for &kb in kbs {
                let l = envelope_at(&live.points, kb);
                let p = envelope_at(&peer.points, kb);
                let past = |e: &Envelope| e.points.last().is_some_and(|p| kb > p.0);
                deltas.push(Delta {
                    peer: peer.tool.clone(),
                    kb,
                    live: l,
                    peer_psnr: p,
                    delta_db: l.zip(p).map(|(l, p)| l - p),
                    beyond: past(live) || past(peer),
                });
            }
        }
    }
    RdSummary {
        set: set.to_string(),
        basis: basis.to_string(),
        envelopes,
        deltas,
    }
}

/// The summaries of every set, raw and gzip.
pub fn summarise(means: &[RdMean], sets: &[(String, usize)], kbs: &[f64]) -> Vec<RdSummary> {
    let mut out = Vec::new();
    for (set, _) in sets {
        for basis in ["raw", "gzip"] {
            out.push(summarise_set(means, set, basis, kbs));
        }
    }
    out
}

fn opt(v: Option<f64>, width: usize, prec: usize) -> String {
    match v {
        Some(v) => format!("{v:>width$.prec$}"),
        None => format!("{:>width$}", "—"),
    }
}

/// The text report: skipped peers, then per set its means, envelopes and differences.
pub fn print_tables(
    sets: &[(String, usize)],
    means: &[RdMean],
    summaries: &[RdSummary],
    skipped: &[(String, String)],
    all_rows: bool,
) {
    for (tool, why) in skipped {
        println!("SKIP {tool}: {why}");
    }
    for (set, n) in sets {
        let set_summaries: Vec<&RdSummary> = summaries.iter().filter(|s| &s.set == set).collect();
        print_means(set, *n, means, &set_summaries, all_rows);
        for s in set_summaries {
            print_envelopes(s);
            print_deltas(s);
        }
    }
    println!(
        "\n(dB; —: a curve does not reach that size; *: past the largest point of a curve, read flat)"
    );
}

/// The means table of one set: live's rows and the peers' envelope points (every row with
/// `all_rows`).
fn print_means(set: &str, n: usize, means: &[RdMean], summaries: &[&RdSummary], all_rows: bool) {
    let on_envelope = |m: &RdMean| {
        summaries.iter().any(|s| {
            s.envelopes
                .iter()
                .any(|e| e.tool == m.tool && e.settings.contains(&m.setting))
        })
    };
    let rows: Vec<&RdMean> = means
        .iter()
        .filter(|m| m.set == set && (all_rows || m.tool == "live" || on_envelope(m)))
        .collect();
    let hidden = means.iter().filter(|m| m.set == set).count() - rows.len();
    println!("\n== set {set}: {n} images, means ==");
    if hidden > 0 {
        println!("({hidden} peer settings on no envelope left out; --all-rows shows them)");
    }
    println!(
        "{:12} {:24} {:>6} {:>7} {:>6} {:>8} {:>7} {:>6} {:>6} {:>6} {:>6} {:>7}",
        "tool",
        "setting",
        "paths",
        "PSNR",
        "SSIM",
        "bytes",
        "gz",
        "colors",
        "selfx",
        "hidden",
        "sliver",
        "seconds"
    );
    for m in rows {
        println!(
            "{:12} {:24} {:>6.1} {:>7.2} {:>6.4} {:>8.0} {:>7.0} {} {} {} {} {:>7.3}",
            m.tool,
            m.setting,
            m.paths,
            m.psnr,
            m.ssim,
            m.svg_bytes,
            m.svg_gz_bytes,
            opt(m.colors, 6, 1),
            opt(m.self_intersecting, 6, 1),
            opt(m.hidden, 6, 1),
            opt(m.slivers, 6, 1),
            m.seconds
        );
    }
}

/// Every tool's envelope points on one set and basis.
fn print_envelopes(s: &RdSummary) {
    println!("-- R–D envelopes, {} KB: (KB, PSNR dB) --", s.basis);
    for e in &s.envelopes {
        let pts: Vec<String> = e
            .points
            .iter()
            .map(|(x, y)| format!("({x:.2}, {y:.2})"))
            .collect();
        println!("{:12} {}", e.tool, pts.join(" "));
    }
}

/// `live − peer` at each size, one row per peer (nothing without peers).
fn print_deltas(s: &RdSummary) {
    let mut kbs: Vec<f64> = Vec::new();
    let mut peers: Vec<&str> = Vec::new();
    for d in &s.deltas {
        if !kbs.contains(&d.kb) {
            kbs.push(d.kb);
        }
        if !peers.contains(&d.peer.as_str()) {
            peers.push(&d.peer);
        }
    }
    if peers.is_empty() {
        return;
    }
    let head: Vec<String> = kbs
        .iter()
        .map(|k| format!("{:>8}", format!("{k}KB")))
        .collect();
    println!(
        "{:18} {}",
        format!("live − peer, {}", s.basis),
        head.join(" ")
    );
    for p in peers {
        let row: Vec<String> = s
            .deltas
            .iter()
            .filter(|d| d.peer == p)
            .map(|d| match d.delta_db {
                Some(v) => format!(
                    "{:>8}",
                    format!("{v:+.2}{}", if d.beyond { "*" } else { " " })
                ),
                None => format!("{:>8}", "— "),
            })
            .collect();
        println!("{:18} {}", p, row.join(" "));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_keeps_the_pareto_frontier() {
        let env = envelope(vec![
            (4.0, 25.0),
            (2.0, 20.0),
            (3.0, 19.0), // beaten by (2, 20)
            (8.0, 30.0),
            (6.0, 24.0), // beaten by (4, 25)
            (2.0, 21.0),
        ]);
        assert_eq!(env, vec![(2.0, 21.0), (4.0, 25.0), (8.0, 30.0)]);
        assert_eq!(envelope_at(&env, 1.0), None);
        assert_eq!(envelope_at(&env, 2.0), Some(21.0));
        assert_eq!(envelope_at(&env, 3.0), Some(23.0));
        assert_eq!(envelope_at(&env, 6.0), Some(27.5));
        assert_eq!(envelope_at(&env, 20.0), Some(30.0));
        assert_eq!(envelope_at(&[], 2.0), None);
    }
}
