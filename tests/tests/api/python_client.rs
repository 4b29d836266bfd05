//! The pip-installable Python client (`clients/python/`) against a real server: a fresh
//! virtual environment made with `ISORAY_PYTHON`'s interpreter, `pip install ./clients/python`
//! (which brings `requests` and NumPy from the package's own dependencies), then the client's
//! own tests (`unittest`) with `ISORAY_URL` naming the server: create a scene, push `.npy`
//! steps from NumPy arrays, render them into NumPy images, delete it, and the server's 4xx
//! answers as exceptions naming the field.

use super::*;

/// Runs `program args` in `dir`, returning (success, stdout + stderr).
fn run(program: &Path, args: &[&str], dir: &Path, env: &[(&str, &str)]) -> (bool, String) {
    let out = Command::new(program)
        .args(args)
        .current_dir(dir)
        .envs(env.iter().copied())
        .output()
        .unwrap_or_else(|e| panic!("{} runs: {e}", program.display()));
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), text)
}

/// Copies the files of `from` (no build output) into `to`.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read dir") {
        let entry = entry.expect("entry");
        let name = entry.file_name();
        let name_str = name.to_string_lossy();
        if name_str == "build" || name_str == "__pycache__" || name_str.ends_with(".egg-info") {
            continue;
        }
        let path = entry.path();
        if path.is_dir() {
            copy_tree(&path, &to.join(&name));
        } else {
            std::fs::copy(&path, to.join(&name)).expect("copy");
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn python_client_installs_with_pip_and_its_tests_pass_against_the_server() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("data");
    std::fs::create_dir_all(&data).expect("data dir");
    let server = Server::start(&data, &[]).await;
    let work = dir.path().to_path_buf();
    let base = server.base.clone();
    let (ok, log) = call(move || {
        // A copy of the package, so pip's in-tree build leaves the checkout clean.
        copy_tree(
            &repo_root().join("clients").join("python"),
            &work.join("clients").join("python"),
        );
        let (ok, log) = run(Path::new(&python()), &["-m", "venv", "venv"], &work, &[]);
        assert!(ok, "a fresh virtual environment: {log}");
        let venv_python = work.join("venv").join("bin").join("python");
        let (ok, log) = run(
            &venv_python,
            &[
                "-m",
                "pip",
                "install",
                "--disable-pip-version-check",
                "./clients/python",
            ],
            &work,
            &[],
        );
        assert!(ok, "pip install ./clients/python: {log}");
        // The tests import the installed package, not the copy: they run from `tests/`.
        let tests = work.join("clients").join("python").join("tests");
        let tests = tests.to_str().expect("utf-8 path").to_string();
        run(
            &venv_python,
            &[
                "-m", "unittest", "discover", "-v", "-s", &tests, "-t", &tests,
            ],
            &work.join("venv"),
            &[("ISORAY_URL", &base)],
        )
    })
    .await;
    assert!(ok, "the client's tests pass against the server:\n{log}");
    // All of them ran: none skipped, the server tests included.
    assert!(log.contains("Ran 4 tests"), "{log}");
    assert!(!log.contains("skipped"), "{log}");
    for name in [
        "test_create_push_render_delete",
        "test_bad_input_names_the_field",
        "test_every_filter_type_round_trips",
    ] {
        assert!(
            log.lines()
                .any(|l| l.starts_with(name) && l.trim_end().ends_with("... ok")),
            "{name} passed: {log}"
        );
    }
    server.stop().await;
}
