//! Bytes per path of the SVG writer: `cargo run --example svg_bytes -- a.svg b.svg …` reads each
//! SVG, writes it again in the old plain format (absolute `M x y C …`, `#rrggbb`, every attribute
//! per path) and with the compact writer, and prints bytes per path for each.

use std::fmt::Write as _;
use vectorfusion::scene::{Rgba, Scene};
use vectorfusion::svg::{SvgOptions, from_svg, to_svg};
use vectorfusion::vector::export::compact_svg;

/// The writer as it was before the compact format, as a yardstick.
fn plain(scene: &Scene, prec: usize) -> String {
    let n = |v: f32| {
        let s = format!("{v:.prec$}");
        let s = if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        };
        if s == "-0" { "0".into() } else { s }
    };
    let hex = |c: Rgba| {
        let b = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
        format!("#{:02x}{:02x}{:02x}", b(c.r), b(c.g), b(c.b))
    };
    let (w, h) = (scene.width, scene.height);
    let mut o = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" viewBox=\"0 0 {w} {h}\">\n"
    );
    if scene.background.a > 0.0 {
        let _ = writeln!(
            o,
            "<rect width=\"{w}\" height=\"{h}\" fill=\"{}\"/>",
            hex(scene.background)
        );
    }
    for sh in &scene.shapes {
        let p = sh.points[0];
        let _ = write!(o, "<path d=\"M{} {}", n(p.x), n(p.y));
        for i in 0..sh.num_segments() {
            let s = sh.segment(i);
            let _ = write!(
                o,
                "C{} {} {} {} {} {}",
                n(s[1].x),
                n(s[1].y),
                n(s[2].x),
                n(s[2].y),
                n(s[3].x),
                n(s[3].y)
            );
        }
        if sh.is_closed() {
            o.push('Z');
        }
        o.push('"');
        if let Some(f) = sh.fill.filter(|f| f.a > 0.0) {
            let _ = write!(o, " fill=\"{}\"", hex(f));
            if f.a < 1.0 {
                let a = format!("{:.*}", prec.max(2), f.a);
                let a = a.trim_end_matches('0').trim_end_matches('.');
                let _ = write!(o, " fill-opacity=\"{a}\"");
            }
        } else {
            o.push_str(" fill=\"none\"");
        }
        if let Some(st) = sh.stroke {
            let _ = write!(
                o,
                " stroke=\"{}\" stroke-width=\"{}\" stroke-linecap=\"round\" stroke-linejoin=\"round\"",
                hex(st.color),
                n(st.width)
            );
        }
        o.push_str("/>\n");
    }
    o.push_str("</svg>\n");
    o
}

fn main() {
    println!(
        "file paths | old p1 | new p1 | old p2 | new p2 | new p2 grouped | compact (1/k px grid: k)  [bytes per path]"
    );
    for path in std::env::args().skip(1) {
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{path}: {e}");
                continue;
            }
        };
        let scene = match from_svg(&text) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{path}: {e}");
                continue;
            }
        };
        let k = scene.shapes.len().max(1) as f64;
        let per = |s: &str| s.len() as f64 / k;
        let new = |precision, group_by_color| {
            to_svg(
                &scene,
                &SvgOptions {
                    precision,
                    group_by_color,
                    ..SvgOptions::default()
                },
            )
        };
        let c = compact_svg(&scene, &SvgOptions::default());
        println!(
            "{path} {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} ({})",
            scene.shapes.len(),
            per(&plain(&scene, 1)),
            per(&new(1, false)),
            per(&plain(&scene, 2)),
            per(&new(2, false)),
            per(&new(2, true)),
            per(&c.svg),
            c.units_per_px
        );
    }
}
