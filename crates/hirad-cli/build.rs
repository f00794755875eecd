//! Embeds the commit the binary is built from (`HIRAD_BUILD_COMMIT`: 12 hex digits, with
//! `-dirty` when tracked files differ from it) so that run records name the code that ran,
//! whatever the checkout holds when the binary runs. Outside a git checkout: the build
//! environment's `HIRAD_GIT_COMMIT`, else `unknown`.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

fn main() {
    println!("cargo:rerun-if-env-changed=HIRAD_GIT_COMMIT");
    // Any source change of the workspace may flip the dirty flag.
    println!("cargo:rerun-if-changed=..");
    let commit = match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(c) => {
            if let Some(dir) = git(&["rev-parse", "--absolute-git-dir"]) {
                println!("cargo:rerun-if-changed={dir}/HEAD");
                println!("cargo:rerun-if-changed={dir}/index");
                if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
                    println!("cargo:rerun-if-changed={dir}/{r}");
                }
            }
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty {
                format!("{c}-dirty")
            } else {
                c
            }
        }
        None => std::env::var("HIRAD_GIT_COMMIT")
            .ok()
            .filter(|c| !c.trim().is_empty())
            .unwrap_or_else(|| "unknown".into()),
    };
    println!("cargo:rustc-env=HIRAD_BUILD_COMMIT={commit}");
}
