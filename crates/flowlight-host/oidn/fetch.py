#!/usr/bin/env python3
"""Fetches Intel Open Image Denoise 2.5.1 for `flowlight render --denoise`, when neither
OIDN_DIR nor a system libOpenImageDenoise is there (docs/denoising.md).

The library comes from the PyPI wheel pyoidn==2.5.1.0 (fetched with pip, its sha256 pinned
and checked by pip's --require-hashes), which carries libOpenImageDenoise.so.2.5.1, its core
and CPU device, and the TBB they need. Those files are unpacked into target/oidn/lib of the
repository (or $FLOWLIGHT_OIDN_FETCH_DIR/lib), where the renderer looks for them at run
time; the GPU devices (CUDA, HIP, SYCL) are left out. Idempotent: does nothing when the
files are already there.
"""
import os, subprocess, sys, tempfile, zipfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.normpath(os.path.join(HERE, "..", "..", ".."))
REQUIREMENT = ("pyoidn==2.5.1.0 --hash=sha256:"
               "32ad13368f8de1ef63001942ad05b02a00cd732d1206d97f352d3a3f606d823e")
# Wheel member -> file name in lib/ (the SONAMEs the libraries ask for).
MEMBERS = {
    "pyoidn/oidn/lib/libOpenImageDenoise.so.2.5.1": "libOpenImageDenoise.so.2.5.1",
    "pyoidn/oidn/lib/libOpenImageDenoise_core.so.2.5.1": "libOpenImageDenoise_core.so.2.5.1",
    "pyoidn/oidn/lib/libOpenImageDenoise_device_cpu.so.2.5.1":
        "libOpenImageDenoise_device_cpu.so.2.5.1",
    "pyoidn/oidn/lib/libtbb.so.12.19": "libtbb.so.12",
}
LINKS = {"libOpenImageDenoise.so.2": "libOpenImageDenoise.so.2.5.1"}


def main():
    root = os.environ.get("FLOWLIGHT_OIDN_FETCH_DIR") or os.path.join(REPO, "target", "oidn")
    lib = os.path.join(root, "lib")
    wanted = list(MEMBERS.values()) + list(LINKS)
    if all(os.path.exists(os.path.join(lib, f)) for f in wanted):
        return
    os.makedirs(lib, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        req = os.path.join(tmp, "requirements.txt")
        with open(req, "w") as f:
            f.write(REQUIREMENT + "\n")
        print("fetch-oidn: downloading pyoidn 2.5.1.0 (Open Image Denoise)", file=sys.stderr)
        subprocess.run([sys.executable, "-m", "pip", "download", "--quiet",
                        "--disable-pip-version-check", "--no-deps", "--require-hashes",
                        "--only-binary=:all:", "-r", req, "-d", tmp], check=True)
        wheel = next(os.path.join(tmp, n) for n in os.listdir(tmp) if n.endswith(".whl"))
        with zipfile.ZipFile(wheel) as z:
            for member, name in MEMBERS.items():
                dest = os.path.join(lib, name)
                with z.open(member) as src, open(dest + ".part", "wb") as out:
                    out.write(src.read())
                os.chmod(dest + ".part", 0o755)
                os.replace(dest + ".part", dest)
    for link, target in LINKS.items():
        path = os.path.join(lib, link)
        if os.path.lexists(path):
            os.remove(path)
        os.symlink(target, path)
    print(f"fetch-oidn: Open Image Denoise 2.5.1 in {lib}", file=sys.stderr)


if __name__ == "__main__":
    main()
