#!/usr/bin/env python3
"""Fetches the glTF 2.0 test models of Debian's `assimp-testmodels` package into glTF2/ here.

The corpus is what `tests/integration/gltf_corpus.rs` renders: every glTF2 model either renders with no
error or fails with an error naming the unsupported feature, and none renders black without a
warning; docs/gltf.md keeps the list and the outcome. The models are not shipped with
Flowlight (see SOURCE.md for their licences). The package is fetched with `apt-get download`
at a pinned version and checked against a pinned sha256, then only usr/share/assimp/models/
glTF2/ is unpacked (dpkg-deb). Idempotent: does nothing when glTF2/ is there and current.
"""
import hashlib, os, shutil, subprocess, sys, tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = "assimp-testmodels=5.2.5~ds0-1"
SHA256 = "526f326186000cd6f631ea806128548a7d3d391abd8149fddc5c4c8513e80b8a"
MEMBER = "usr/share/assimp/models/glTF2"
STAMP = PACKAGE + " " + SHA256


def download(tmp):
    cmd = ["apt-get", "download", "-q", PACKAGE]
    r = subprocess.run(cmd, cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    if r.returncode != 0:
        # A fresh machine may have no package lists yet.
        sudo = [] if os.geteuid() == 0 else ["sudo"]
        subprocess.run(sudo + ["apt-get", "update", "-qq"], stdout=subprocess.DEVNULL)
        r = subprocess.run(cmd, cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    debs = [f for f in os.listdir(tmp) if f.endswith(".deb")]
    if r.returncode != 0 or not debs:
        msg = r.stderr.decode(errors="replace").strip().splitlines()
        print(f"error: `apt-get download {PACKAGE}` failed ({msg[-1] if msg else 'no output'}); "
              "the glTF corpus test needs Debian's package archive", file=sys.stderr)
        return None
    return os.path.join(tmp, debs[0])


def main():
    out = os.path.join(HERE, "glTF2")
    stamp = os.path.join(HERE, "glTF2.stamp")
    if os.path.isdir(out) and os.path.exists(stamp) and open(stamp).read().strip() == STAMP:
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        deb = download(tmp)
        if deb is None:
            return 1
        digest = hashlib.sha256(open(deb, "rb").read()).hexdigest()
        if digest != SHA256:
            print(f"error: {os.path.basename(deb)} has sha256 {digest}, expected {SHA256}", file=sys.stderr)
            return 1
        root = os.path.join(tmp, "root")
        subprocess.run(["dpkg-deb", "-x", deb, root], check=True)
        staged = os.path.join(HERE, "glTF2.tmp")
        shutil.rmtree(staged, ignore_errors=True)
        shutil.copytree(os.path.join(root, MEMBER), staged)
        shutil.copy(os.path.join(root, "usr/share/doc/assimp-testmodels/copyright"),
                    os.path.join(staged, "COPYRIGHT.debian"))
    shutil.rmtree(out, ignore_errors=True)
    os.replace(staged, out)
    with open(stamp, "w") as f:
        f.write(STAMP + "\n")
    n = sum(f.endswith((".gltf", ".glb")) for _, _, fs in os.walk(out) for f in fs)
    print(f"assimp-testmodels: {n} glTF 2.0 files -> {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
