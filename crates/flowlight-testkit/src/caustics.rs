//! Two caustic scenes kept out of every tuning: no integrator parameter, mutation mix or
//! preset was chosen by looking at them. They are where a method's claim to work on scenes
//! it was not tuned for is checked (docs/results.md reports them before anything else was
//! run on them). Built from numbers with [`SceneBuilder`], y up, metres; each has its MCPT
//! config and a `bdpt.toml` (the method of its reference: light tracing's t = 1 strategy
//! sees a caustic that camera paths find only by hitting the lamp).
//!
//! * `lens-spot`: a plano-convex glass lens held 0.85 m above the floor of a closed room
//!   focuses a small ceiling lamp into a bright spot on the floor (L S S D E), inside the
//!   lens' shadow; the rest of the room is lit directly and by interreflection.
//! * `glass-rod`: a vertical solid glass cylinder on a floor before a wall, lit by a small
//!   lamp low on one side: the rod acts as a cylindrical lens and draws a bright line on the
//!   floor behind it (L S S D E), and a weaker one through internal reflection.

use crate::gltf::SceneBuilder;
use crate::research::{ceiling_lamp, method_config, room, ResearchScene, Tris};
use crate::scenes::{clear, finish, generator, lamp, plain, side_lamp};
use std::f64::consts::TAU;

/// A plano-convex lens: a spherical cap of sphere radius `r` over a flat disc of radius `a`
/// at height `y` centred on the y axis, convex side up; `rings` × `segments` cells, smooth
/// normals on the cap, flat ones on the disc.
fn lens(
    b: &mut SceneBuilder,
    material: &str,
    y: f64,
    r: f64,
    a: f64,
    rings: usize,
    segments: usize,
) {
    let sag = r - (r * r - a * a).sqrt();
    let centre = [0.0, y + sag - r, 0.0];
    let theta_max = (a / r).asin();
    let mut t = Tris::default();
    let top = t.vertex([0.0, y + sag, 0.0], [0.0, 1.0, 0.0]);
    let mut previous: Vec<u32> = vec![top; segments];
    for i in 1..=rings {
        let theta = theta_max * i as f64 / rings as f64;
        let ring: Vec<u32> = (0..segments)
            .map(|k| {
                let phi = TAU * k as f64 / segments as f64;
                let n = [
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                ];
                let p = [
                    centre[0] + r * n[0],
                    centre[1] + r * n[1],
                    centre[2] + r * n[2],
                ];
                t.vertex(p, n)
            })
            .collect();
        for k in 0..segments {
            let k1 = (k + 1) % segments;
            let out = t.positions[ring[k] as usize];
            let facing = [out[0] - centre[0], out[1] - centre[1], out[2] - centre[2]];
            if i == 1 {
                t.tri(top, ring[k], ring[k1], facing);
            } else {
                t.quad([previous[k], ring[k], ring[k1], previous[k1]], facing);
            }
        }
        previous = ring;
    }
    let down = [0.0, -1.0, 0.0];
    let middle = t.vertex([0.0, y, 0.0], down);
    let rim: Vec<u32> = (0..segments)
        .map(|k| {
            let phi = TAU * k as f64 / segments as f64;
            t.vertex([a * phi.cos(), y, a * phi.sin()], down)
        })
        .collect();
    for k in 0..segments {
        t.tri(middle, rim[k], rim[(k + 1) % segments], down);
    }
    t.write(b, material);
}

/// A closed vertical cylinder of radius `r` from `base` up `height`: smooth sides, flat caps.
fn cylinder(
    b: &mut SceneBuilder,
    material: &str,
    base: [f64; 3],
    r: f64,
    height: f64,
    segments: usize,
) {
    let mut t = Tris::default();
    let at = |phi: f64, y: f64| {
        [
            base[0] + r * phi.cos(),
            base[1] + y,
            base[2] + r * phi.sin(),
        ]
    };
    let side: Vec<[u32; 2]> = (0..segments)
        .map(|k| {
            let phi = TAU * k as f64 / segments as f64;
            let n = [phi.cos(), 0.0, phi.sin()];
            [t.vertex(at(phi, 0.0), n), t.vertex(at(phi, height), n)]
        })
        .collect();
    for k in 0..segments {
        let (a, c) = (side[k], side[(k + 1) % segments]);
        let n = t.normals[a[0] as usize];
        t.quad([a[0], c[0], c[1], a[1]], n);
    }
    for (y, n) in [(0.0, [0.0, -1.0, 0.0]), (height, [0.0, 1.0, 0.0])] {
        let middle = t.vertex([base[0], base[1] + y, base[2]], n);
        let rim: Vec<u32> = (0..segments)
            .map(|k| t.vertex(at(TAU * k as f64 / segments as f64, y), n))
            .collect();
        for k in 0..segments {
            t.tri(middle, rim[k], rim[(k + 1) % segments], n);
        }
    }
    t.write(b, material);
}

pub fn lens_spot() -> ResearchScene {
    let mut b = SceneBuilder::new(&generator("lens-spot"));
    b.material("floor", [0.6, 0.58, 0.55], plain());
    b.material("wall", [0.7, 0.7, 0.72], plain());
    b.material("glass", [1.0, 1.0, 1.0], clear(1.5));
    b.material("lamp", [0.0; 3], lamp([1.0, 0.93, 0.8], 400.0));
    room(&mut b, "floor", "wall", [-1.5, 0.0, -1.5], [1.5, 2.4, 1.5]);
    // Sphere radius 0.25 m, aperture radius 0.2 m (sag 10 cm): focal length about
    // 0.25 / (1.5 − 1) = 0.5 m, so the lamp 1.35 m above images 0.79 m below the lens, just
    // above the floor: a spot of about 8 cm.
    lens(&mut b, "glass", 0.85, 0.25, 0.2, 24, 96);
    ceiling_lamp(&mut b, "lamp", 2.3, [-0.06, 0.06], [-0.06, 0.06]);
    let files = finish(
        "lens-spot",
        &b,
        ([1.35, 1.35, -1.4], [0.0, 0.42, 0.0], 55.0),
        "
A lens focusing a lamp: a 3 m square room, 2.4 m high, with diffuse walls and floor, lit only by
a 12 cm square lamp 10 cm under the ceiling's centre, facing down. 0.85 m above the floor under
it a plano-convex glass lens (ior 1.5, convex side up, sphere radius 0.25 m, 0.4 m across;
24 x 96 cells with smooth normals) focuses the lamp into a spot of about 8 cm on the floor, in
the middle of the lens' shadow (L S S D E paths; the lens is held by nothing). Path tracing sees
the spot only when a floor ray refracts through the lens onto the small lamp. Kept out of every
tuning (crates/flowlight-testkit/src/caustics.rs).",
        10,
    );
    method_config(
        files,
        "bdpt.toml",
        "bdpt",
        10,
        "
A lens focusing a lamp rendered with bidirectional path tracing: light subpaths through the lens
reach the floor and connect to the eye (t = 1), the strategy that sees the focused spot.",
    )
}

pub fn glass_rod() -> ResearchScene {
    let mut b = SceneBuilder::new(&generator("glass-rod"));
    b.material("floor", [0.7, 0.7, 0.7], plain());
    b.material("wall", [0.55, 0.6, 0.65], plain());
    b.material("glass", [1.0, 1.0, 1.0], clear(1.5));
    b.material("lamp", [0.0; 3], lamp([1.0, 0.95, 0.85], 300.0));
    b.quad(
        "floor",
        [
            [-3.0, 0.0, -3.0],
            [3.0, 0.0, -3.0],
            [3.0, 0.0, 3.0],
            [-3.0, 0.0, 3.0],
        ],
        Some([0.0, 1.0, 0.0]),
    );
    b.quad(
        "wall",
        [
            [-3.0, 0.0, 1.2],
            [3.0, 0.0, 1.2],
            [3.0, 2.5, 1.2],
            [-3.0, 2.5, 1.2],
        ],
        Some([0.0, 0.0, -1.0]),
    );
    cylinder(&mut b, "glass", [0.0, 0.0, 0.0], 0.15, 0.6, 128);
    // A 0.2 m square lamp 2.5 m from the rod on the −x side, 20° above the floor, facing it.
    side_lamp(&mut b, "lamp", 2.5, 20.0, 0.1);
    let files = finish(
        "glass-rod",
        &b,
        ([0.9, 1.1, -1.9], [0.75, 0.0, 0.0], 45.0),
        "
A glass rod as a cylindrical lens: a solid vertical glass cylinder (ior 1.5, radius 0.15 m,
0.6 m high, 128 smooth sides, flat caps) on a diffuse floor before a wall, lit only by a 0.2 m
square lamp 2.5 m away on its left, 20 degrees above the floor. The rod focuses the lamp into a
bright line on the floor behind it (L S S D E paths), beside its shadow; the camera sees the line
and the rod. Path tracing sees the line only when a floor ray refracts through the rod onto the
small lamp. Kept out of every tuning (crates/flowlight-testkit/src/caustics.rs).",
        10,
    );
    method_config(
        files,
        "bdpt.toml",
        "bdpt",
        10,
        "
A glass rod as a cylindrical lens rendered with bidirectional path tracing: light subpaths
through the rod reach the floor and connect to the eye (t = 1), the strategy that sees the line.",
    )
}
