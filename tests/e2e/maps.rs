//! `iwsim map check` on malformed files, as a careless or hostile user writes them: each is
//! refused with exit code 1 and a `file:line:column:` message, and nothing aborts.

use std::path::PathBuf;

use crate::cli::iwsim;

fn bad_file(name: &str, bytes: &[u8]) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("iwsim-maps-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write temp file");
    path
}

/// Runs `iwsim map check` on `bytes` and returns its stderr, asserting exit code 1.
fn refused(name: &str, bytes: &[u8]) -> (String, String) {
    let path = bad_file(name, bytes);
    let file = path.to_str().expect("utf-8 path").to_owned();
    let out = iwsim(&["map", "check", &file]);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{name}: {err}");
    assert!(!err.contains("panicked") && !err.contains("memory allocation"), "{name}: {err}");
    (file, err)
}

#[test]
fn map_check_refuses_malformed_labs_at_their_line_and_column() {
    let cases: [(&str, &[u8], &str, &str); 6] = [
        ("no-width.xml", b"<Lab Height=\"14\">\n</Lab>\n", ":1:1: ", "no Width attribute"),
        (
            "typo-row.xml",
            b"<Lab Width=\"28\" Height=\"14\">\n<Row Pos=\"3\" Pattern=\"--+#-\"/>\n</Lab>\n",
            ":2:26: ",
            "means nothing",
        ),
        ("garbage.xml", b"\n  this is not a map\n", ":2:3: ", "root element"),
        ("latin1.xml", b"<Lab Name=\"caf\xe9\" Width=\"1\" Height=\"1\"/>\n", ":1:15: ", "not UTF-8"),
        (
            "huge.xml",
            b"<Lab Width=\"10000000\" Height=\"10000000\">\n<Wall><Corner X=\"1\" Y=\"1\"/><Corner X=\"2\" Y=\"1\"/><Corner X=\"2\" Y=\"2\"/></Wall>\n</Lab>\n",
            ":1:1: ",
            "at most 10000",
        ),
        (
            "dtd.xml",
            b"<!DOCTYPE Lab [<!ENTITY e9 \"x\">]>\n<Lab Name=\"&e9;\" Width=\"1\" Height=\"1\"/>\n",
            ":1:1: ",
            "DTDs and entity declarations are not supported",
        ),
    ];
    for (name, bytes, at, says) in cases {
        let (file, err) = refused(name, bytes);
        assert!(err.starts_with(&format!("{file}{at}")), "{name}: {err}");
        assert!(err.contains(says), "{name}: {err}");
    }
}

#[test]
fn map_check_names_a_file_without_a_root_element_once_with_a_space() {
    let (file, err) = refused("empty.xml", b"<!-- nothing here -->\n");
    assert_eq!(
        err.trim_end(),
        format!("{file}: the file holds no root element: expected <Lab>, <Grid> or <Parameters>")
    );
}
