//! The third-party check of a recording: `python/check_recording.py` run with the PyPI `mcap`
//! reader and Foxglove's published schema package. This finds (or makes) the Python that has
//! those packages, so tests, CI and users run the same check.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Why no Python with the checker's packages could be found or made.
#[derive(Debug, thiserror::Error)]
pub enum CheckerPythonError {
    /// A step of making the virtual environment failed.
    #[error("making the Python environment for the recording check: `{command}` failed: {detail}")]
    Setup {
        /// What was run.
        command: String,
        /// What it said (or why it could not run).
        detail: String,
    },
}

/// The folder of the checker script and its `requirements.txt`.
pub fn checker_dir() -> PathBuf {
    workspace().join("hub/recorder/python")
}

/// The workspace's root folder.
fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The checker script, `check_recording.py`.
pub fn checker_script() -> PathBuf {
    checker_dir().join("check_recording.py")
}

/// The requirement files of the project's Python environment: this checker's, the test needs
/// of the `iwsim` Python package (`python/requirements-test.txt`), and the user guide's
/// renderer (`docs/requirements.txt`).
pub fn requirement_files() -> [PathBuf; 3] {
    [
        checker_dir().join("requirements.txt"),
        workspace().join("python/requirements-test.txt"),
        workspace().join("docs/requirements.txt"),
    ]
}

/// A Python with the packages of [`requirement_files`]: `$IWSIM_PYTHON` when set, else
/// `target/pyvenv/bin/python` of this workspace, made on first use with `python3 -m venv` and
/// `pip install -r` each file (one process makes it while others wait on a lock). The venv's
/// marker holds the files' text it was made from, so a changed requirement reinstalls.
pub fn checker_python() -> Result<PathBuf, CheckerPythonError> {
    if let Some(p) = std::env::var_os("IWSIM_PYTHON") {
        return Ok(PathBuf::from(p));
    }
    let venv = workspace().join("target/pyvenv");
    let python = venv.join("bin/python");
    let ready = venv.join(".iwsim-ready");
    let fail = |command: &str, detail: String| CheckerPythonError::Setup { command: command.to_owned(), detail };
    std::fs::create_dir_all(&venv).map_err(|e| fail("mkdir target/pyvenv", e.to_string()))?;
    let lock =
        std::fs::File::create(venv.with_extension("lock")).map_err(|e| fail("lock target/pyvenv", e.to_string()))?;
    lock.lock().map_err(|e| fail("lock target/pyvenv", e.to_string()))?;
    let mut wanted = String::new();
    for f in requirement_files() {
        wanted += &std::fs::read_to_string(&f).map_err(|e| fail(&format!("read {}", f.display()), e.to_string()))?;
    }
    if std::fs::read_to_string(&ready).ok().as_deref() != Some(wanted.as_str()) {
        let run = |program: &Path, args: &[&str]| {
            let what = format!("{} {}", program.display(), args.join(" "));
            let out = Command::new(program).args(args).output().map_err(|e| fail(&what, e.to_string()))?;
            if !out.status.success() {
                return Err(fail(&what, String::from_utf8_lossy(&out.stderr).into_owned()));
            }
            Ok(())
        };
        let venv_s = venv.to_string_lossy().into_owned();
        if !python.exists() {
            run(Path::new("python3"), &["-m", "venv", &venv_s])?;
        }
        for f in requirement_files() {
            let req = f.to_string_lossy().into_owned();
            run(&python, &["-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-r", &req])?;
        }
        std::fs::write(&ready, &wanted).map_err(|e| fail("mark target/pyvenv ready", e.to_string()))?;
    }
    Ok(python)
}
