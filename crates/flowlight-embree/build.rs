//! Provisions Embree 4 for the build, in this order:
//!
//! 1. `EMBREE_DIR`: a user's own Embree 4 install (`$EMBREE_DIR/lib{,64}/libembree4.so`);
//! 2. a system `libembree4.so` that the C toolchain's linker finds;
//! 3. the pinned PyPI wheel `embreex==4.4.0.post1` (sha256-checked by pip), whose
//!    `embreex.libs/` holds `libembree4-4aef3270.so.4` and `libtbb-dcf63f8c.so.12`; both are
//!    unpacked with Python's `zipfile` into `$OUT_DIR/embree/lib`, with a `libembree4.so`
//!    link for the linker.
//!
//! The library is opened at run time (dlopen) from the absolute path found here, which is
//! compiled into the crate (`FLOWLIGHT_EMBREE_LIB`); Embree's own RPATH (`$ORIGIN`) finds
//! TBB beside it. So no `LD_LIBRARY_PATH` is needed, and a binary that cannot open it falls
//! back to the BVH under `intersector = "auto"`.
//!
//! `FLOWLIGHT_EMBREE_SKIP_SYSTEM=1` skips step 2 (to exercise the wheel path on a machine
//! that has a system Embree).

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

const WHEEL_REQ: &str = "embreex==4.4.0.post1 --hash=sha256:2cd0f7d5c6342e6247e31f700761689cae7829454d8c6de0c41e62124a023e1f";
const WHEEL_LIBS: [&str; 2] = [
    "embreex.libs/libembree4-4aef3270.so.4",
    "embreex.libs/libtbb-dcf63f8c.so.12",
];
const WHEEL_EMBREE: &str = "libembree4-4aef3270.so.4";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    println!("cargo:rerun-if-env-changed=FLOWLIGHT_EMBREE_SKIP_SYSTEM");
    println!("cargo:rerun-if-env-changed=PYTHON");

    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    let (source, link_dir, runtime_lib) = if let Some(dir) = env::var_os("EMBREE_DIR") {
        from_embree_dir(Path::new(&dir))
    } else if let Some(found) = (env::var_os("FLOWLIGHT_EMBREE_SKIP_SYSTEM").is_none())
        .then(system_embree)
        .flatten()
    {
        found
    } else {
        from_wheel(&out)
    };

    if let Some(dir) = &link_dir {
        // embree4-sys asks for `-lembree4`; this is where the linker finds it. No symbol is
        // referenced at link time (functions are resolved at run time), so the
        // `--as-needed` link drops it from the binaries' DT_NEEDED.
        println!("cargo:rustc-link-search=native={}", dir.display());
    }
    println!("cargo:rustc-env=FLOWLIGHT_EMBREE_LIB={runtime_lib}");
    println!("cargo:rustc-env=FLOWLIGHT_EMBREE_SOURCE={source}");
}

fn fail(msg: &str) -> ! {
    eprintln!(
        "\nerror: flowlight-embree could not provision Embree 4: {msg}\n\n\
         Point EMBREE_DIR at an Embree 4 install (the folder holding lib/libembree4.so, e.g. an\n\
         unpacked embree-4.x.y.x86_64.linux release), then rebuild:\n\n    \
         EMBREE_DIR=/opt/embree-4.4.0 cargo build --workspace\n"
    );
    panic!("Embree 4 not provisioned: {msg}; set EMBREE_DIR to an Embree 4 install");
}

fn from_embree_dir(dir: &Path) -> (&'static str, Option<PathBuf>, String) {
    for sub in ["lib", "lib64", "."] {
        let d = dir.join(sub);
        let dev = d.join("libembree4.so");
        if dev.exists() {
            let d = d.canonicalize().unwrap_or(d);
            // Prefer the SONAME file, the one a binary would have been linked against.
            let rt = ["libembree4.so.4", "libembree4.so"]
                .iter()
                .map(|n| d.join(n))
                .find(|p| p.exists())
                .unwrap();
            return ("EMBREE_DIR", Some(d), rt.display().to_string());
        }
    }
    fail(&format!(
        "EMBREE_DIR={} has no lib/libembree4.so (nor lib64/ or the folder itself)",
        dir.display()
    ));
}

/// A `libembree4.so` on the linker's default search path: the C compiler's library
/// directories (`cc -print-file-name`), then `ld`'s `SEARCH_DIR`s (e.g. `/usr/local/lib`).
fn system_embree() -> Option<(&'static str, Option<PathBuf>, String)> {
    let cc = env::var("CC").unwrap_or_else(|_| "cc".into());
    let mut dirs = Vec::new();
    if let Ok(o) = Command::new(cc)
        .arg("-print-file-name=libembree4.so")
        .output()
    {
        let p = PathBuf::from(String::from_utf8_lossy(&o.stdout).trim());
        if let Some(d) = p
            .is_absolute()
            .then(|| p.parent().map(Path::to_path_buf))
            .flatten()
        {
            dirs.push(d);
        }
    }
    if let Ok(o) = Command::new("ld").arg("--verbose").output() {
        let text = String::from_utf8_lossy(&o.stdout);
        for part in text.split("SEARCH_DIR(\"").skip(1) {
            if let Some(d) = part.split('"').next() {
                dirs.push(PathBuf::from(d.trim_start_matches('=')));
            }
        }
    }
    let dir = dirs
        .into_iter()
        .find(|d| d.join("libembree4.so").exists())?;
    let dev = dir.join("libembree4.so");
    let rt = if dir.join("libembree4.so.4").exists() {
        dir.join("libembree4.so.4")
    } else {
        dev
    };
    Some(("system", Some(dir), rt.display().to_string()))
}

fn from_wheel(out: &Path) -> (&'static str, Option<PathBuf>, String) {
    let lib = out.join("embree").join("lib");
    let target = lib.join(WHEEL_EMBREE);
    if !(target.exists() && lib.join("libtbb-dcf63f8c.so.12").exists()) {
        let wheel_dir = out.join("wheel");
        let _ = std::fs::remove_dir_all(&wheel_dir);
        std::fs::create_dir_all(&wheel_dir).unwrap();
        let req = out.join("embree-requirements.txt");
        std::fs::write(&req, format!("{WHEEL_REQ}\n")).unwrap();
        let python = env::var("PYTHON").unwrap_or_else(|_| "python3".into());
        let status = Command::new(&python)
            .args([
                "-m",
                "pip",
                "download",
                "--quiet",
                "--disable-pip-version-check",
                "--no-deps",
                "--require-hashes",
                "--only-binary=:all:",
                "--platform",
                "manylinux_2_28_x86_64",
                "--python-version",
                "3.11",
                "--implementation",
                "cp",
                "--abi",
                "cp311",
                "-d",
            ])
            .arg(&wheel_dir)
            .arg("-r")
            .arg(&req)
            .status();
        match status {
            Ok(s) if s.success() => {}
            Ok(s) => fail(&format!(
                "`{python} -m pip download embreex==4.4.0.post1` failed ({s})"
            )),
            Err(e) => fail(&format!("could not run `{python} -m pip`: {e}")),
        }
        std::fs::create_dir_all(&lib).unwrap();
        let script = format!(
            "import glob, os, sys, zipfile\n\
             w = glob.glob(os.path.join(sys.argv[1], 'embreex-*.whl'))[0]\n\
             z = zipfile.ZipFile(w)\n\
             for name in {WHEEL_LIBS:?}:\n    \
                 dst = os.path.join(sys.argv[2], os.path.basename(name))\n    \
                 open(dst + '.tmp', 'wb').write(z.read(name))\n    \
                 os.chmod(dst + '.tmp', 0o755)\n    \
                 os.replace(dst + '.tmp', dst)\n"
        );
        let status = Command::new(&python)
            .arg("-c")
            .arg(script)
            .arg(&wheel_dir)
            .arg(&lib)
            .status();
        if !matches!(status, Ok(s) if s.success()) {
            fail("unpacking the embreex wheel with Python's zipfile failed");
        }
        let _ = std::fs::remove_dir_all(&wheel_dir);
    }
    let link = lib.join("libembree4.so");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(WHEEL_EMBREE, &link).unwrap();
    (
        "wheel embreex==4.4.0.post1",
        Some(lib),
        target.display().to_string(),
    )
}
