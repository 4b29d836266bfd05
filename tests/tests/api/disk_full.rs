//! A full disk: the test mounts a small tmpfs (CI runs as root) as the data directory. A push
//! or a scene creation that runs out of space gets 507 with a clear message, leaves no
//! `.tmp-` file behind, changes nothing stored, and what is stored is still served.

use super::*;
use std::process::Command;

/// A tmpfs of `size` mounted on a fresh directory, unmounted when dropped.
struct SmallDisk {
    dir: tempfile::TempDir,
}

impl SmallDisk {
    fn mount(size: &str) -> SmallDisk {
        let dir = tempfile::tempdir().expect("temp dir");
        let out = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir.path())
            .output()
            .expect("mount runs");
        assert!(
            out.status.success(),
            "mounting a tmpfs needs root (CI runs as root): {}",
            String::from_utf8_lossy(&out.stderr)
        );
        SmallDisk { dir }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.dir.path()).status();
    }
}

fn balls(n: usize, seed: f32) -> Vec<u8> {
    let values: Vec<f32> = (0..n)
        .flat_map(|i| {
            let a = i as f32 * 0.01 + seed;
            [a.cos(), a.sin(), (a * 3.0).sin() * 0.2, 0.05]
        })
        .collect();
    npy(&values, 4)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_full_disk_is_a_507_that_changes_nothing_stored() {
    let disk = SmallDisk::mount("512k");
    let root = disk.path().to_path_buf();
    let server = Server::start(&root, &[]).await;
    let base = server.base.clone();
    call(move || {
        let (id, token) = create(&base);
        let small = balls(1000, 0.0); // 16 KB
        let r = push(&base, &id, "0", &token, NPY, &small);
        assert_eq!(r.status, 201, "{}", r.text());
        let before = store_snapshot(&root);

        // 40 000 balls, 640 KB: more than the disk holds.
        let r = push(&base, &id, "1", &token, NPY, &balls(40_000, 1.0));
        assert_eq!(r.status, 507, "{}", r.text());
        assert_eq!(json(&r)["code"], "storage_full", "{}", r.text());
        assert!(r.text().contains("full"), "{}", r.text());
        assert_eq!(
            temp_files(&root),
            Vec::<PathBuf>::new(),
            "no temporary file left"
        );
        assert_eq!(store_snapshot(&root), before, "nothing stored changed");
        let listed: Vec<u64> = steps(&base, &id)
            .as_array()
            .expect("steps")
            .iter()
            .map(|s| s["index"].as_u64().expect("index"))
            .collect();
        assert_eq!(listed, [0], "the stored step is still listed");
        let r = get(&base, &format!("/api/v1/scenes/{id}/steps/0/data"));
        assert_eq!(r.status, 200, "and served");

        // Fill what is left, then create a scene: 507, and no `.tmp-<id>` directory left.
        let filler = root.join("filler");
        let mut f = std::fs::File::create(&filler).expect("filler");
        let chunk = vec![0u8; 4096];
        while std::io::Write::write_all(&mut f, &chunk).is_ok() {}
        drop(f);
        let before = store_snapshot(&root);
        let r = Client::new(&base)
            .expect("url")
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs","name":"no room"}"#),
            )
            .expect("answer");
        assert_eq!(r.status, 507, "{}", r.text());
        assert_eq!(json(&r)["code"], "storage_full");
        assert_eq!(
            temp_files(&root),
            Vec::<PathBuf>::new(),
            "no .tmp- directory left"
        );
        assert_eq!(store_snapshot(&root), before, "nothing stored changed");
        let r = get(&base, &format!("/api/v1/scenes/{id}/steps/0/data"));
        assert_eq!(r.status, 200, "the stored step is still served");
    })
    .await;
    server.stop().await;
    drop(disk);
}
