//! Writes the benchmark scenes of `scenes/suite.toml` (glTF 2.0 with an embedded buffer, and
//! a render config each), deterministically:
//!
//! ```text
//! cargo run -p flowlight-testkit --bin make-scenes            # rewrites scenes/<name>/<name>.{gltf,toml}
//! cargo run -p flowlight-testkit --bin make-scenes -- DIR     # writes DIR/<name>/… instead
//! ```
//!
//! Scenes (y up, metres):
//!
//! * `indirect-room`: a room lit only from a lamp hidden in a back room behind a partition
//!   with a doorway: nearly all light seen from the camera arrives after 2+ bounces.
//! * `glass-caustic`: a smooth glass sphere (KHR_materials_transmission, ior 1.5) on a
//!   diffuse floor under a small lamp: the caustic under the sphere is made of LSDE paths.
//! * `mirror-chain`: a narrow corridor between two parallel perfect mirrors (metallic 1,
//!   roughness 0): camera rays at the image edge bounce more than 10 times before reaching
//!   the diffuse floor or end wall.
//! * `narrow-gap`: a slab 2 cm above the floor in a corner, lit from above: the floor under
//!   it is lit only through the 2 cm gaps (the thesis' corner and cavity traps).
//! * `ring-caustic`: a polished metal ring (open cylinder) on a diffuse floor, lit by a small
//!   lamp at a low angle: the cardioid caustic inside the ring is made of LSDE paths.
//!
//!
//! and the research scenes of the bidirectional integrators (`src/research.rs` describes
//! them), each with a second config for the method it is shown with (`bdpt.toml` or
//! `vcm.toml`): `veach-door`, `water-pool`, `veach-mis` and `lamp-shade`; and the two caustic
//! scenes kept out of every tuning (`src/caustics.rs`), `lens-spot` and `glass-rod`.
//!
//! `tests/scenes.rs` of this crate checks that the committed files are what this writes.

use std::path::Path;

fn main() {
    let out = std::env::args()
        .nth(1)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(flowlight_testkit::scenes_dir);
    for (name, text_gltf, text_toml, triangles) in flowlight_testkit::scenes::all() {
        let files = [
            (format!("{name}.gltf"), text_gltf),
            (format!("{name}.toml"), text_toml),
        ];
        write_or_exit(&out, name, &files, triangles);
    }
    for scene in flowlight_testkit::research::all() {
        let (name, text_gltf, text_toml, triangles) = scene.files;
        let (method_file, method_text) = scene.method_config;
        let files = [
            (format!("{name}.gltf"), text_gltf),
            (format!("{name}.toml"), text_toml),
            (method_file.to_string(), method_text),
        ];
        write_or_exit(&out, name, &files, triangles);
    }
}

fn write_or_exit(out: &Path, name: &str, files: &[(String, String)], triangles: usize) {
    if let Err(e) = write(out, name, files) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
    println!("{name:<14} {triangles:>5} triangles");
}

fn write(out: &Path, name: &str, files: &[(String, String)]) -> Result<(), String> {
    let folder = out.join(name);
    std::fs::create_dir_all(&folder).map_err(|e| format!("{}: {e}", folder.display()))?;
    for (file, text) in files {
        let p = folder.join(file);
        std::fs::write(&p, text).map_err(|e| format!("{}: {e}", p.display()))?;
    }
    Ok(())
}
