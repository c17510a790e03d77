//! The `iwsim` Python package, tested by its own pytest suite (`python/tests`) against real hub
//! processes over shared memory: the suite runs in the project's Python environment
//! (`target/pyvenv`, with numpy, pytest, Gymnasium and PettingZoo) on the native module built
//! from this very tree (`lib_iwsim.so` of the `iwsim-python` package), so a Rust change is
//! always tested from Python too, without a separate wheel build.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::common::text;

/// The newest modification time of the Rust sources the native module is built from.
fn sources_changed(root: &Path) -> std::time::SystemTime {
    let mut newest = std::time::SystemTime::UNIX_EPOCH;
    for dir in ["python/src", "agents/agent-sdk/src", "libs/observer/src", "ipc-types/src", "libs/ipc-services/src"] {
        for entry in std::fs::read_dir(root.join(dir)).into_iter().flatten().flatten() {
            if let Ok(t) = entry.metadata().and_then(|m| m.modified()) {
                newest = newest.max(t);
            }
        }
    }
    newest
}

/// The native module of this source tree. `cargo test --workspace` builds it with everything
/// else (the `iwsim-python` package's integration test makes cargo build its library, cdylib
/// included, into `target/debug/deps`); when it is missing or older than its sources (only
/// this test was asked for), it is built here, into a target folder of its own
/// (`target/python-module`: the outer `cargo test` holds `target/`'s lock). Never a stale wheel.
fn native_module(root: &Path) -> PathBuf {
    let bin_dir = PathBuf::from(env!("CARGO_BIN_EXE_iwsim")).parent().expect("target/debug").to_path_buf();
    let built = bin_dir.join("deps/lib_iwsim.so");
    let fresh = |p: &Path| p.metadata().and_then(|m| m.modified()).is_ok_and(|t| t >= sources_changed(root));
    if fresh(&built) {
        return built;
    }
    let target = root.join("target/python-module");
    let out = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "--locked", "-p", "iwsim-python", "--target-dir"])
        .arg(&target)
        .current_dir(root)
        .output()
        .expect("cargo runs");
    assert!(out.status.success(), "building the Python module failed:\n{}", text(&out.stderr));
    let native = target.join("debug/lib_iwsim.so");
    assert!(native.exists(), "{} is missing after the build", native.display());
    native
}

/// A package folder `iwsim/` made of `python/iwsim/*.py` and this tree's native module, in a
/// fresh temporary directory (what `pip install ./python` installs, without the wheel).
fn package_from_this_build(root: &Path) -> PathBuf {
    let native = native_module(root);
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
    let python = test_support::python::checker_python().unwrap_or_else(|e| panic!("{e}"));
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
