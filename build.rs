//! Records the commit the binary is built from, so a run's manifest names the code that made
//! it even when the binary runs outside its checkout ("unknown" where the sources are not a
//! git checkout, e.g. a packaged crate).

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let revision = git(&["rev-parse", "HEAD"]).unwrap_or_else(|| "unknown".into());
    // Only what is compiled counts: specs, results and documents do not change the binary.
    let dirty = git(&[
        "status",
        "--porcelain",
        "--",
        "src",
        "build.rs",
        "Cargo.toml",
        "Cargo.lock",
    ])
    .map_or("unknown", |s| if s.is_empty() { "false" } else { "true" });
    println!("cargo:rustc-env=FACELAB_BUILD_REVISION={revision}");
    println!("cargo:rustc-env=FACELAB_BUILD_DIRTY={dirty}");
    for path in ["src", "build.rs", "Cargo.toml", "Cargo.lock"] {
        println!("cargo:rerun-if-changed={path}");
    }
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        // A commit moves HEAD (or the branch it names) and rewrites the index.
        for file in ["HEAD", "index"] {
            println!("cargo:rerun-if-changed={dir}/{file}");
        }
        if let Some(head) = git(&["symbolic-ref", "-q", "HEAD"]) {
            println!("cargo:rerun-if-changed={dir}/{head}");
        }
    }
}
