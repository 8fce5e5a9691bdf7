//! Editability counts ([`vectorfusion::vector::check::check_svg`]) of SVG files, one JSON line
//! each, then the totals: `cargo run --release --example editability -- a.svg b.svg …`.

fn main() {
    let mut total = vectorfusion::vector::check::Editability::default();
    let mut files = 0;
    for path in std::env::args().skip(1) {
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{path}: {e}");
                std::process::exit(2);
            }
        };
        match vectorfusion::vector::check::check_svg(&text) {
            Ok(e) => {
                println!(
                    "{}",
                    serde_json::json!({"file": path, "bytes": text.len(), "editability": e})
                );
                total.paths += e.paths;
                total.self_intersecting += e.self_intersecting;
                total.hidden += e.hidden;
                total.slivers += e.slivers;
                total.colors += e.colors;
                files += 1;
            }
            Err(e) => {
                eprintln!("{path}: {e}");
                std::process::exit(2);
            }
        }
    }
    println!("{}", serde_json::json!({"files": files, "total": total}));
}
