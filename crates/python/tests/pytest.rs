//! Runs the Python module's pytest suite (`tests/test_scbg.py`) against the built wheel.
//!
//! `.ci/run` builds the wheel with maturin (sharing `target/`) and installs it into the
//! virtualenv `target/py-venv` before `cargo test`. Without that virtualenv this test makes it
//! itself — maturin then builds in `target/maturin` (cargo holds `target/` while tests run), so
//! the first local run takes minutes.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn run(cmd: &mut Command, what: &str) {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn imports_scbg(python: &Path) -> bool {
    Command::new(python)
        .args([
            "-c",
            "import scbg, numpy, pytest, highway_env, libsumo, sumolib",
        ])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn build_venv(root: &Path, venv: &Path) {
    eprintln!(
        "building the scbg wheel into {} (first run: minutes)",
        venv.display()
    );
    if !venv.join("bin/python").exists() {
        run(
            Command::new("python3").args(["-m", "venv"]).arg(venv),
            "python3 -m venv",
        );
    }
    let python = venv.join("bin/python");
    run(
        Command::new(&python).args([
            "-m",
            "pip",
            "install",
            "-q",
            "maturin>=1.5,<2",
            "numpy",
            "pytest",
            "highway-env",
            "eclipse-sumo",
            "libsumo",
            "sumolib",
        ]),
        "pip install maturin numpy pytest highway-env eclipse-sumo libsumo sumolib",
    );
    let wheels = root.join("target/wheels");
    run(
        Command::new(venv.join("bin/maturin"))
            .args(["build", "--release", "-q", "-m"])
            .arg(root.join("crates/python/Cargo.toml"))
            .arg("--out")
            .arg(&wheels)
            .env("CARGO_TARGET_DIR", root.join("target/maturin")),
        "maturin build",
    );
    let wheel = std::fs::read_dir(&wheels)
        .unwrap()
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "whl"))
        .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
        .expect("maturin wrote a wheel");
    run(
        Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "-q",
                "--force-reinstall",
                "--no-deps",
            ])
            .arg(&wheel),
        "pip install the wheel",
    );
}

#[test]
fn python_module_passes_its_pytest_suite() {
    let root = root();
    let venv = root.join("target/py-venv");
    let python = venv.join("bin/python");
    if !imports_scbg(&python) {
        build_venv(&root, &venv);
    }
    let bin = root.join("target/release/scbg");
    assert!(
        bin.exists(),
        "{} missing (cargo test --release builds it)",
        bin.display()
    );
    let out = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("crates/python/tests"))
        .env("SCBG_BIN", &bin)
        .env(
            "SCBG_TINY_CONFIG",
            root.join("crates/lab/tests/tiny_train.toml"),
        )
        .output()
        .expect("run pytest");
    let text = format!(
        "{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!("{text}");
    assert!(out.status.success(), "pytest failed:\n{text}");
    assert!(
        text.contains("passed") && !text.contains("skipped"),
        "{text}"
    );
}
