//! The `iwsim` Python package, tested by its own pytest suite (`python/tests`) against real hub
//! processes over shared memory: the suite runs in the project's Python environment
//! (`target/pyvenv`, with numpy and pytest) on the native module this very build made
//! (`lib_iwsim.so` of the `iwsim-python` package), so a Rust change is always tested from
//! Python too, without a separate wheel build.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::common::text;

/// A package folder `iwsim/` made of `python/iwsim/*.py` and this build's native module, in a
/// fresh temporary directory (what `pip install ./python` installs, without the wheel).
fn package_from_this_build(root: &Path) -> PathBuf {
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_iwsim"));
    let native = bin.with_file_name("lib_iwsim.so");
    assert!(
        native.exists(),
        "{} is missing: `cargo test --workspace` builds it (or `cargo build -p iwsim-python`)",
        native.display()
    );
    let dir = std::env::temp_dir().join(format!("iwsim-e2e-python-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let pkg = dir.join("iwsim");
    std::fs::create_dir_all(&pkg).expect("temp dir");
    for entry in std::fs::read_dir(root.join("python/iwsim")).expect("python/iwsim") {
        let path = entry.expect("entry").path();
        if path.extension().is_some_and(|e| e == "py") {
            std::fs::copy(&path, pkg.join(path.file_name().expect("name"))).expect("copied");
        }
    }
    std::fs::copy(&native, pkg.join("_iwsim.so")).expect("native module copied");
    dir
}

#[test]
fn the_python_packages_own_tests_pass_against_real_hubs() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = recorder::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
    let dir = package_from_this_build(root);
    let out = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("python/tests"))
        .env("PYTHONPATH", &dir)
        .env("IWSIM_BIN", env!("CARGO_BIN_EXE_iwsim"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("pytest runs");
    let _ = std::fs::remove_dir_all(&dir);
    let (stdout, stderr) = (text(&out.stdout), text(&out.stderr));
    assert!(out.status.success(), "pytest failed\n{stdout}\n{stderr}");
    assert!(stdout.contains(" passed"), "{stdout}");
}
