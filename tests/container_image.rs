//! The scale-out image (`Containerfile`) built and run: a Debian bookworm base made with `debootstrap` from the Debian mirror (no container registry is needed), `podman build --isolation chroot` on it with the errmap binary under test, the image exported and the sample job run inside it in a chroot (where `podman run` is not permitted), its maps and program byte-equal to the same job run on the host. Skipped without root, podman or debootstrap, unless ERRMAP_REQUIRE_PODMAN=1.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// The local base image the build starts from; kept between runs as a cache.
const BASE_IMAGE: &str = "localhost/errmap-base:bookworm";

/// Where debootstrap downloads from (`ERRMAP_DEBIAN_MIRROR` overrides it).
const DEFAULT_MIRROR: &str = "http://deb.debian.org/debian";

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn on_path(tool: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(tool).is_file()))
}

/// Why the test cannot run here, if it cannot.
fn missing() -> Option<String> {
    let uid = Command::new("id").arg("-u").output().ok()?;
    if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
        return Some("not root (debootstrap and chroot need it)".into());
    }
    for tool in ["podman", "debootstrap", "chroot", "tar"] {
        if !on_path(tool) {
            return Some(format!("no `{tool}` (apt-get install podman debootstrap)"));
        }
    }
    None
}

/// Run a command to completion; panic with its output when it fails.
#[track_caller]
fn run(cmd: &mut Command, what: &str) -> String {
    let out = cmd
        .output()
        .unwrap_or_else(|e| panic!("{what}: cannot start: {e}"));
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The Debian base image: debootstrap's minimal bookworm with lavapipe, imported into podman
/// once and reused (the download takes minutes).
fn ensure_base_image() {
    let exists = Command::new("podman")
        .args(["image", "exists", BASE_IMAGE])
        .status()
        .is_ok_and(|s| s.success());
    if exists {
        return;
    }
    let mirror = std::env::var("ERRMAP_DEBIAN_MIRROR").unwrap_or_else(|_| DEFAULT_MIRROR.into());
    let dir = tempfile::tempdir().unwrap();
    let rootfs = dir.path().join("rootfs");
    run(
        Command::new("debootstrap")
            .args([
                "--variant=minbase",
                "--include=mesa-vulkan-drivers,libvulkan1,ca-certificates",
                "bookworm",
            ])
            .arg(&rootfs)
            .arg(&mirror),
        "debootstrap",
    );
    // The package cache is not part of the image.
    let _ = std::fs::remove_dir_all(rootfs.join("var/cache/apt/archives"));
    let _ = std::fs::remove_dir_all(rootfs.join("var/lib/apt/lists"));
    let mut tar = Command::new("tar")
        .arg("-C")
        .arg(&rootfs)
        .args(["-c", "."])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let import = Command::new("podman")
        .args(["import", "-", BASE_IMAGE])
        .stdin(tar.stdout.take().unwrap())
        .output()
        .unwrap();
    assert!(
        tar.wait().unwrap().success(),
        "tar of the debootstrap tree failed"
    );
    assert!(
        import.status.success(),
        "podman import failed: {}",
        String::from_utf8_lossy(&import.stderr)
    );
}

/// The image's file system, exported from a container of it.
fn export_image(image: &str, rootfs: &Path) {
    let id = run(
        Command::new("podman").args(["create", image]),
        "podman create",
    );
    let id = id.trim();
    std::fs::create_dir_all(rootfs).unwrap();
    let mut export = Command::new("podman")
        .args(["export", id])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let untar = Command::new("tar")
        .arg("-x")
        .arg("-C")
        .arg(rootfs)
        .stdin(export.stdout.take().unwrap())
        .status()
        .unwrap();
    let exported = export.wait().unwrap();
    let _ = Command::new("podman").args(["rm", id]).output();
    assert!(
        exported.success() && untar.success(),
        "podman export | tar -x failed"
    );
}

/// `errmap ARGS` inside the image's file system, from its working directory /work.
fn errmap_in_chroot(rootfs: &Path, args: &[&str]) -> std::process::Output {
    Command::new("chroot")
        .arg(rootfs)
        .args([
            "/bin/sh",
            "-c",
            "PATH=/usr/local/bin:/usr/bin:/bin; cd /work && exec errmap \"$@\"",
            "sh",
        ])
        .args(args)
        .env("ERRMAP_CACHE_DIR", "/tmp/errmap-cache")
        .output()
        .unwrap()
}

/// Copy a folder with its subfolders.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_tree(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// Every file under `dir` with a name ending in one of `suffixes`, relative to `dir`, sorted.
fn files(dir: &Path, suffixes: &[&str]) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p);
            } else if suffixes.iter().any(|s| p.to_string_lossy().ends_with(s)) {
                found.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    found.sort();
    found
}

#[test]
fn the_image_built_from_a_debootstrap_base_runs_the_sample_job_as_the_host_does() {
    if let Some(why) = missing() {
        if std::env::var("ERRMAP_REQUIRE_PODMAN").as_deref() == Ok("1") {
            panic!("ERRMAP_REQUIRE_PODMAN=1 but the image cannot be built here: {why}");
        }
        eprintln!("SKIPPED container_image: {why}");
        return;
    }
    ensure_base_image();

    // The build context: the repository's Containerfile and the binary under test.
    let ctx = tempfile::tempdir().unwrap();
    std::fs::copy(
        root().join("Containerfile"),
        ctx.path().join("Containerfile"),
    )
    .unwrap();
    std::fs::create_dir(ctx.path().join("bin")).unwrap();
    std::fs::copy(env!("CARGO_BIN_EXE_errmap"), ctx.path().join("bin/errmap")).unwrap();
    let image = format!("localhost/errmap:test-{}", std::process::id());
    run(
        Command::new("podman")
            .args(["build", "--isolation", "chroot", "-q"])
            .args(["--build-arg", &format!("BASE={BASE_IMAGE}")])
            .args(["--build-arg", "ERRMAP_BIN=bin/errmap"])
            .args(["-t", &image, "-f"])
            .arg(ctx.path().join("Containerfile"))
            .arg(ctx.path()),
        "podman build",
    );
    let scratch = tempfile::tempdir().unwrap();
    let rootfs = scratch.path().join("rootfs");
    export_image(&image, &rootfs);
    let _ = Command::new("podman").args(["rmi", &image]).output();

    // The sample job inside the image, as the manifests run it from /work.
    copy_tree(
        &root().join("data/web-plate"),
        &rootfs.join("work/data/web-plate"),
    );
    let inside = errmap_in_chroot(
        &rootfs,
        &[
            "batch",
            "data/web-plate/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
            "out/cpu",
            "-q",
        ],
    );
    assert!(
        inside.status.success(),
        "the sample job failed inside the image:\n{}",
        String::from_utf8_lossy(&inside.stderr)
    );
    // The same job on the host: the image must give the same bytes (same binary, same backend).
    let host_out = scratch.path().join("host");
    let host = common::command()
        .current_dir(root())
        .args([
            "batch",
            "data/web-plate/job.toml",
            "--backend",
            "cpu",
            "--out-dir",
        ])
        .arg(&host_out)
        .arg("-q")
        .output()
        .unwrap();
    assert!(
        host.status.success(),
        "{}",
        String::from_utf8_lossy(&host.stderr)
    );
    let image_out = rootfs.join("work/out/cpu");
    let compared = files(&host_out, &["map.csv", ".ngc"]);
    assert!(
        compared.len() >= 9,
        "the sample job's maps and program: {compared:?}"
    );
    assert_eq!(compared, files(&image_out, &["map.csv", ".ngc"]));
    for f in &compared {
        assert!(
            std::fs::read(host_out.join(f)).unwrap() == std::fs::read(image_out.join(f)).unwrap(),
            "{} differs between the image and the host",
            f.display()
        );
    }

    // Lavapipe inside the image: the GPU backend trains on software Vulkan there.
    let gpu = errmap_in_chroot(
        &rootfs,
        &[
            "batch",
            "data/web-plate/job.toml",
            "--backend",
            "gpu",
            "--out-dir",
            "out/gpu",
            "-q",
        ],
    );
    assert!(
        gpu.status.success(),
        "the GPU backend failed inside the image:\n{}",
        String::from_utf8_lossy(&gpu.stderr)
    );
    let run_json = std::fs::read_to_string(rootfs.join("work/out/gpu/run.json")).unwrap();
    assert!(
        run_json.contains("\"backend\": \"gpu: llvmpipe"),
        "the image's GPU backend is not lavapipe: {run_json}"
    );
}
