//! `isoray push` of molecules: a real PDB entry from Debian's pymol-data (1TII, 5,469 atoms
//! without waters) and the same structure as mmCIF, written by gemmi from it, push as
//! metaball scenes and render the molecule; a truncated file and a malformed coordinate are
//! refused naming the line. `isoray render` of the file gives the server's image.

use super::*;
use crate::e2e::support::pixel_stddev;

const PDB: &str = "/usr/share/pymol/test/dat/1tii.pdb";

/// Pushes `file`, renders step 0 small; returns the atoms pushed and the image.
fn push_and_render(base: &str, file: &Path) -> (u64, image::RgbImage) {
    let (ok, text) = push_files(base, &[file]);
    assert!(ok, "{}: {text}", file.display());
    let id = created_scene_id(&text);
    let atoms: u64 = text
        .split(", ")
        .find_map(|p| p.strip_suffix(" atoms"))
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the atom count is printed: {text}"));
    let img = image::load_from_memory(&render_png(base, &id, 0))
        .expect("png")
        .to_rgb8();
    (atoms, img)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pdb_and_mmcif_files_push_and_render_and_bad_lines_are_named() {
    let dir = tempfile::tempdir().expect("temp dir");
    let cif = dir.path().join("1tii.cif");
    let script = format!(
        "import gemmi, sys\nst = gemmi.read_structure({PDB:?})\nst.remove_waters()\n\
         st.setup_entities()\nst.make_mmcif_document().write_file(sys.argv[1])\n"
    );
    let out = Command::new(python())
        .args(["-c", &script])
        .arg(&cif)
        .output()
        .expect("python runs (CI installs gemmi, and pymol-data with apt)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(PDB).expect("pymol-data's 1tii.pdb");
    let lines: Vec<&str> = text.lines().collect();
    let first_atom = lines
        .iter()
        .position(|l| l.starts_with("ATOM"))
        .expect("ATOM records");
    // Cut inside the third atom's y coordinate; and a letter inside the second's x.
    let truncated = dir.path().join("truncated.pdb");
    let mut cut = lines[..first_atom + 2].join("\n");
    cut.push('\n');
    cut.push_str(&lines[first_atom + 2][..40]);
    std::fs::write(&truncated, cut).expect("write");
    let malformed = dir.path().join("malformed.pdb");
    let mut bad: Vec<String> = lines[..first_atom + 5]
        .iter()
        .map(|l| l.to_string())
        .collect();
    bad[first_atom + 1].replace_range(32..33, "x");
    std::fs::write(&malformed, bad.join("\n")).expect("write");

    let server = Server::start(&dir.path().join("data"), &[]).await;
    let base = server.base.clone();
    let dir_path = dir.path().to_path_buf();
    call(move || {
        let (atoms, pdb_image) = push_and_render(&base, Path::new(PDB));
        // 5,684 atom records, 215 of them waters (counted from the file's columns by grep).
        assert_eq!(atoms, 5469, "1TII's atoms without hydrogens and waters");
        assert!(pixel_stddev(&pdb_image) > 5.0, "the molecule shows");
        // `isoray render` of the same file, offline, gives the server's image byte for byte.
        let png = dir_path.join("1tii.png");
        let out = Command::new(isoray_binary())
            .arg("render")
            .arg(PDB)
            .args(["--width", "48", "--height", "36", "--output"])
            .arg(&png)
            .output()
            .expect("isoray render runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let offline = image::open(&png).expect("a png").to_rgb8();
        assert!(
            offline == pdb_image,
            "isoray render and POST .../render differ"
        );
        let (cif_atoms, cif_image) = push_and_render(&base, &cif);
        assert!(cif_atoms > 5000, "{cif_atoms}");
        assert!(pixel_stddev(&cif_image) > 5.0, "the molecule shows");

        let (ok, text) = push_files(&base, &[&truncated]);
        assert!(!ok);
        let line = format!("line {}", first_atom + 3);
        assert!(
            text.contains("truncated.pdb") && text.contains(&line),
            "{line}: {text}"
        );
        let (ok, text) = push_files(&base, &[&malformed]);
        assert!(!ok);
        let line = format!("line {}", first_atom + 2);
        assert!(
            text.contains("malformed.pdb") && text.contains(&line),
            "{line}: {text}"
        );
        // `isoray render` names the line too, and writes no image.
        let out = Command::new(isoray_binary())
            .arg("render")
            .arg(&malformed)
            .arg("--output")
            .arg(dir_path.join("bad.png"))
            .output()
            .expect("isoray render runs");
        let text = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(text.contains(&line), "{line}: {text}");
        assert!(!dir_path.join("bad.png").exists());
    })
    .await;
    server.stop().await;
}
