//! Embeds the browser client: lists every file at the top of `client-web/` (HTML, JavaScript
//! modules, CSS, SVG) into `$OUT_DIR/client_files.rs`, so a new client module is served without
//! editing `web.rs`, and `isoray` runs from any directory.

use std::fmt::Write as _;
use std::path::Path;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let dir = Path::new(&manifest).join("..").join("client-web");
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .expect("client-web/ is part of the repository")
        .filter_map(|entry| {
            let entry = entry.ok()?;
            let name = entry.file_name().into_string().ok()?;
            (entry.file_type().ok()?.is_file() && mime(&name).is_some()).then_some(name)
        })
        .collect();
    names.sort();
    let mut out = String::from("/// (path, content type, bytes) of every client file.\npub const FILES: &[(&str, &str, &[u8])] = &[\n");
    for name in &names {
        let path = dir.join(name);
        println!("cargo:rerun-if-changed={}", path.display());
        let mime = mime(name).expect("filtered above");
        writeln!(
            out,
            "    ({name:?}, {mime:?}, include_bytes!({:?})),",
            path.display().to_string()
        )
        .expect("writing to a String cannot fail");
    }
    out.push_str("];\n");
    let target =
        Path::new(&std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("client_files.rs");
    std::fs::write(target, out).expect("OUT_DIR is writable");
}

/// Content type of a client file, or `None` for files that are not served.
fn mime(name: &str) -> Option<&'static str> {
    let ext = name.rsplit_once('.')?.1;
    Some(match ext {
        "html" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "svg" => "image/svg+xml",
        _ => return None,
    })
}
