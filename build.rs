//! Build facts for `jointd_build_info`: the git revision of the tree being
//! built and the compiler's version, as compile-time environment variables.
//! Nothing here may fail the build: a tarball or a Docker build has no
//! `.git` (the image's `.dockerignore` leaves it out), a machine may have no
//! `git`; then the revision is "unknown".

use std::path::Path;
use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let dir = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_else(|_| ".".to_owned());
    let dir = Path::new(&dir);
    // Only this crate's own checkout: a parent repository's HEAD (the crate
    // vendored somewhere) would name a revision that is not this tree's.
    let revision = if dir.join(".git").exists() {
        watch_git_head(dir);
        git(dir, &["rev-parse", "--short", "HEAD"])
    } else {
        None
    };
    let revision = revision.unwrap_or_else(|| "unknown".to_owned());
    println!("cargo:rustc-env=JOINTD_GIT_REVISION={revision}");
    println!("cargo:rustc-env=JOINTD_RUSTC_VERSION={}", rustc_version());
    // The features cargo enabled, as cargo tells build scripts: the test of
    // the label compares the `cfg!` list with this independent one.
    let mut features: Vec<String> = std::env::vars()
        .filter_map(|(k, _)| k.strip_prefix("CARGO_FEATURE_").map(feature_name))
        .collect();
    features.sort();
    println!(
        "cargo:rustc-env=JOINTD_CARGO_FEATURES={}",
        features.join(",")
    );
}

/// `CARGO_FEATURE_FOO_BAR` names the feature `foo-bar` (or `foo_bar`;
/// this crate has neither).
fn feature_name(var: &str) -> String {
    var.to_ascii_lowercase().replace('_', "-")
}

/// Output of `git args` in `dir`, trimmed; `None` if git is missing or fails.
fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .args(args)
        .current_dir(dir)
        .output()
        .ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    let text = text.trim();
    (out.status.success() && !text.is_empty()).then(|| text.to_owned())
}

/// Builds again when HEAD moves: a commit, a checkout. Only files that exist
/// are named (cargo would rebuild every time for a missing one); in a git
/// worktree HEAD and the branch's ref live in different directories, which
/// `--git-path` resolves.
fn watch_git_head(dir: &Path) {
    let mut paths = vec!["HEAD".to_owned(), "packed-refs".to_owned()];
    if let Some(branch) = git(dir, &["symbolic-ref", "-q", "HEAD"]) {
        paths.push(branch);
    }
    for p in paths {
        let Some(file) = git(dir, &["rev-parse", "--git-path", &p]) else {
            continue;
        };
        let file = dir.join(file);
        if file.exists() {
            println!("cargo:rerun-if-changed={}", file.display());
        }
    }
}

/// `1.85.0` from `rustc 1.85.0 (4d91de4e4 2025-02-17)`, or "unknown".
fn rustc_version() -> String {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".to_owned());
    Command::new(rustc)
        .arg("--version")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|v| v.split_whitespace().nth(1).map(str::to_owned))
        .unwrap_or_else(|| "unknown".to_owned())
}
