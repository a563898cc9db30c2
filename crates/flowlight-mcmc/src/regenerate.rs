//! The prefix-regeneration engine behind every unidirectional mutation (thesis §5.4–5.5).
//!
//! A proposal y is built from the current path x from the eye: the raster position migrates
//! inside its film window, the eye ray gives y₁, and then, vertex by vertex,
//!
//! * a Dirac vertex is followed deterministically (its lobe must match x's);
//! * at a smooth vertex y_j the path either **reconnects** hard to x_{j+1} — y keeps x's
//!   vertices from j+1 on (a Dirac step: T = 1) — with probability p_r, or is **extended** by
//!   sampling a direction: from the BSDF (free extension) or uniformly in a spherical cap
//!   around the direction to x_{j+1} (soft reconnection, a "drill" step);
//! * reaching xₙ's position in the sequence, the extension must hit an emitter.
//!
//! Every new vertex must have x's weak node type, and the path keeps its length: otherwise the
//! proposal is a domain miss. Reconnection needs smooth (or light) vertices on both ends.
//!
//! **Dirac chains of any length** ([`Policy::free_chains`]). A chain of Dirac vertices is a
//! deterministic function of the ray that enters it, so the number of its vertices is not a
//! coordinate of the path measure: with the eye ray's raster position u and the free vertices
//! (those after a smooth vertex) as coordinates, E S S D … and E S D … are points of one
//! space, and a move that changes u alone has the same density T₀(u → u') whatever the two
//! paths' numbers of mirror bounces. So, with `free_chains`, a chain is followed through
//! *forced* Dirac vertices — a surface that emits nothing, has no smooth component and one
//! Dirac lobe for the arriving direction (a mirror; glass, with its choice of reflection or
//! refraction, is not forced) — as far as they go, and the vertex that ends it need only
//! have the weak type of the vertex that ends x's chain (smooth, or the light); the vertices
//! after it are x's, shifted. The densities are the fixed-length ones: the film term, and at
//! each extension p_ω · J of the chain's first vertex (the chain's other vertices are not
//! free). It applies to paths whose every Dirac vertex is forced, and a proposal must be of
//! the same kind as x (both forced, or both not) so that the reverse move is the same rule;
//! other paths keep Veach's fixed lengths. The lighting layer is recomputed (the mirror
//! bounces seen from the eye are not counted, those after the first smooth vertex are), and
//! the integrator must refuse proposals beyond its seeds' depth limits
//! ([`within_depth`]).
//!
//! Densities are in the target function's measure ([`crate::measure`]): an extension step has
//! T = (1 − p_r) · p_ω · J, with J the area Jacobian of the new vertex; a reconnection step
//! has T = p_r. The reverse move regenerates x from y with the same rules: for the cap, the
//! cap is centred on the direction from x_j to y_{j+1}. The strategies differ only by their
//! [`Policy`].
//!
//! **Lights at infinity** (the measure is in [`crate::measure`]'s module docs):
//!
//! * a *directional* light's vertex is a Dirac in direction: like a point light's, no mutation
//!   moves it. A smooth vertex whose successor is a Dirac light (point, spot, directional)
//!   always reconnects (p_r = 1 whatever the policy: an extension could never reach the
//!   light), and the reconnection to a directional light is an unbounded shadow ray along the
//!   light's direction;
//! * the *environment*'s vertex is a free direction ω in the solid-angle measure, so mutations
//!   perturb it like any free vertex: a hard reconnection keeps ω (a Dirac step, T = p_r, with
//!   the shadow ray unbounded along ω); an extension at x_{n−1} must escape the scene, and the
//!   direction it escaped along is the new ω, with T = (1 − p_r)·p_ω — no area Jacobian, the
//!   measure of ω being solid angle; a Dirac chain (or the eye ray) that escapes reaches the
//!   environment along the direction it is forced into. The cap of a cap extension is centred
//!   on ω itself. Regenerating ω freshly from the environment's own sampling density would be
//!   correct too (an independence move for the last vertex), but it ignores the BSDF and the
//!   current direction, so most proposals would land where the path's f is small.

use crate::measure::{
    area_jacobian, dirac_component, dirac_scatter, direction, distant_vertex, is_distant,
    light_index, local_directions_towards, same_vertex, side_consistent, vertex_bsdf, WeakNode,
};
use crate::migration;
use crate::perturbation::{ExpCone, LensJump};
use flowlight_core::bsdf::Bsdf;
use flowlight_core::geometry::{offset_ray_origin, Frame, Ray, SurfaceHit};
use flowlight_core::light::LightKind;
use flowlight_core::path::{NodeType, Path, PathVertex, MAX_PATH_VERTICES};
use flowlight_core::rng::Rng;
use flowlight_core::sampling::{uniform_cone, uniform_cone_pdf};
use flowlight_sdk::{Proposal, Scene, Tracer};
use glam::Vec3;

/// How an extension step chooses its direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Extension {
    /// Sample the BSDF's smooth components (free extension).
    Bsdf,
    /// Uniform in the cap of half-angle acos(`cos_max`) around the direction to the original
    /// path's next vertex (soft reconnection).
    Cap {
        /// Cosine of the cap's half-angle.
        cos_max: f32,
    },
    /// Veach's exponential cone around the direction to the original path's next vertex
    /// (the multi-chain perturbation, [`crate::perturbation`]).
    Cone(ExpCone),
    /// The exponential cone around the original path's own direction at this vertex (x_j →
    /// x_{j+1}): where the eye ray's jump moved y_j a little, the new direction stays
    /// parallel to the old one instead of turning to aim at x_{j+1}, which turns it by
    /// |y_j − x_j| / |x_{j+1} − x_j| — a large angle when the next vertex is near, such as a
    /// mirror beside a floor point, and at the end of a long specular chain a miss of the
    /// light. Symmetric like [`Extension::Cone`]: the reverse move centres its cone on y's
    /// direction, and the ratio is J(x)/J(y).
    ConeAlong(ExpCone),
}

/// A move of the raster position: the first step of every proposal the engine builds
/// ([`propose_with`], [`density_with`]). The engine treats it as *symmetric* — its density
/// satisfies T(u → u') = T(u' → u) for the window K a chain carries — and leaves the film
/// term out of the transition ratio; it enters the density, which a mixture of strategies
/// needs. [`FilmMove`] is the engine's own; a plugin may bring its own (a Gaussian jump,
/// say) by implementing this trait.
pub trait RasterMove {
    /// The moved raster position of path `x` (`x.raster`, chain window `x.film_window`) on a
    /// `width` × `height` film; `None` for a move off the film or outside the window (a
    /// domain miss).
    fn sample(&self, x: &Path, width: u32, height: u32, rng: &mut Rng) -> Option<glam::Vec2>;

    /// Density per unit raster area of moving `x.raster` to `y.raster` (0 where `sample`
    /// cannot land).
    fn density(&self, x: &Path, y: &Path, width: u32, height: u32) -> f64;
}

/// How the raster position moves at the start of a proposal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FilmMove {
    /// Film-plane migration, uniform in the chain's K×K window ([`crate::migration`]).
    Window,
    /// Veach's lens jump, bounded by the film window ([`crate::perturbation::LensJump`]).
    Lens(LensJump),
}

impl RasterMove for FilmMove {
    fn sample(&self, x: &Path, w: u32, h: u32, rng: &mut Rng) -> Option<glam::Vec2> {
        match self {
            FilmMove::Window => migration::migrate(x.raster, x.film_window, w, h, rng),
            FilmMove::Lens(j) => j.sample(x.raster, x.film_window, w, h, rng),
        }
    }

    fn density(&self, x: &Path, y: &Path, w: u32, h: u32) -> f64 {
        match self {
            FilmMove::Window => migration::density(x.raster, y.raster, x.film_window, w, h),
            FilmMove::Lens(j) => j.density(x.raster, y.raster, x.film_window, w, h),
        }
    }
}

impl Extension {
    /// A cap of the given half-angle in degrees.
    pub fn cap_degrees(degrees: f32) -> Extension {
        Extension::Cap {
            cos_max: degrees.to_radians().cos(),
        }
    }
}

/// What distinguishes one mutation strategy from another.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Policy {
    /// Extensions to make before a reconnection may happen.
    pub min_extensions: u32,
    /// Probability of reconnecting at a smooth vertex once `min_extensions` are done.
    pub p_reconnect: f32,
    /// `None`: the strategy never extends (strict hard reconnection).
    pub extension: Option<Extension>,
    /// Never reconnect while the rest of the original path holds a Dirac vertex: caustic
    /// paths are drilled until they reach the light.
    pub drill_caustics: bool,
    /// Follow forced Dirac chains to whatever length they have instead of requiring x's
    /// (module docs, "Dirac chains of any length"). `false`: Veach's rule.
    pub free_chains: bool,
}

/// Whether a path of `vertex_count` vertices and lighting layer `layer` is one the seed
/// samplers can produce with lighting depth `path_depth` and physical depth `max_ray_depth`
/// (every scattering vertex counted). Proposals with free chain lengths can leave that set,
/// and the chains' target is f restricted to it.
pub fn within_depth(vertex_count: u32, layer: u32, path_depth: u32, max_ray_depth: u32) -> bool {
    layer <= path_depth && vertex_count.saturating_sub(2) <= max_ray_depth
}

/// Lighting layer of a path (virtual length − 1): its interior vertices but the leading
/// Dirac ones, which a chain of mirrors seen from the camera does not count
/// (`flowlight_pathtrace`'s lighting depth).
pub fn lighting_layer(v: &[PathVertex]) -> u32 {
    if v.len() < 2 {
        return 0;
    }
    let interior = &v[1..v.len() - 1];
    let leading = interior
        .iter()
        .take_while(|x| WeakNode::of(x).is_dirac())
        .count();
    (interior.len() - leading) as u32
}

/// The one Dirac lobe a ray arriving from `wo` (local frame) must follow at a surface of
/// `bsdf`: (component, transmission). `None` when the BSDF has a smooth component, or
/// several Dirac lobes are possible (glass: reflection or refraction), or none.
pub fn forced_lobe(bsdf: &Bsdf, wo: Vec3) -> Option<(usize, bool)> {
    if bsdf.has_non_delta() {
        return None;
    }
    let mut found = None;
    for (i, (c, w)) in bsdf.components().enumerate() {
        if w <= 0.0 {
            continue;
        }
        for transmission in [false, true] {
            if dirac_scatter(&c, wo, transmission).is_some() {
                if found.is_some() {
                    return None;
                }
                found = Some((i, transmission));
            }
        }
    }
    found
}

/// Whether the stored Dirac vertex `v`, reached from `prev`, is forced: no emission and
/// [`forced_lobe`] is the lobe it took.
fn forced_vertex(scene: &Scene, v: &PathVertex, prev: Vec3) -> bool {
    let kind = WeakNode::of(v);
    if !kind.is_dirac() || v.emitter >= 0 {
        return false;
    }
    let Some(bsdf) = vertex_bsdf(scene, v) else {
        return false;
    };
    let Some(wo) = (prev - v.p).try_normalize() else {
        return false;
    };
    forced_lobe(&bsdf, Frame::from_z(v.ns).to_local(wo))
        == Some((v.component as usize, kind == WeakNode::DiracTransmission))
}

/// Whether every Dirac vertex of the path is forced: the paths free chain lengths apply to.
pub fn all_forced(scene: &Scene, v: &[PathVertex]) -> bool {
    (1..v.len().saturating_sub(1))
        .filter(|&k| WeakNode::of(&v[k]).is_dirac())
        .all(|k| forced_vertex(scene, &v[k], v[k - 1].p))
}

/// The first index ≥ `from` of a vertex that is not a Dirac vertex (the end of a chain).
fn chain_end(v: &[PathVertex], from: usize) -> usize {
    (from..v.len())
        .find(|&k| !WeakNode::of(&v[k]).is_dirac())
        .unwrap_or(v.len() - 1)
}

/// Probability of reconnecting at smooth vertex `j` of `x` after `extensions` extensions. 1
/// when the next vertex is a Dirac light, which only a reconnection reaches (module docs).
fn p_reconnect(scene: &Scene, policy: &Policy, x: &[PathVertex], j: usize, extensions: u32) -> f32 {
    let n = x.len() - 1;
    if !WeakNode::of(&x[j + 1]).connectable() {
        return 0.0;
    }
    if policy.extension.is_none()
        || light_index(scene, &x[j + 1]).is_some_and(|i| scene.lights.kind(i).is_delta())
    {
        return 1.0;
    }
    if extensions < policy.min_extensions {
        return 0.0;
    }
    if policy.drill_caustics && x[j + 1..n].iter().any(|v| WeakNode::of(v).is_dirac()) {
        return 0.0;
    }
    policy.p_reconnect
}

/// Density of extending from `from` (with previous vertex `prev`) to `to`; for a cap or a
/// cone, centred on the direction from `from` to `target` (the other path's next vertex) —
/// or, for [`Extension::ConeAlong`], from `counterpart` (the other path's vertex standing
/// where `from` stands) to `target`: the other path's own direction. Solid angle times the
/// area Jacobian of `to` (times 1 when `to` is a direction at infinity, whose measure is solid
/// angle).
fn extension_density(
    scene: &Scene,
    ext: Extension,
    prev: &PathVertex,
    from: &PathVertex,
    to: &PathVertex,
    counterpart: &PathVertex,
    target: &PathVertex,
) -> f64 {
    let Some(dir) = direction(scene, from, to) else {
        return 0.0;
    };
    let Some((_, _, wi_w, wo, wi)) = local_directions_towards(from, prev.p, dir) else {
        return 0.0;
    };
    let p_omega = match ext {
        Extension::Bsdf => {
            let Some(bsdf) = vertex_bsdf(scene, from) else {
                return 0.0;
            };
            smooth_pdf(&bsdf, wo, wi)
        }
        Extension::Cap { cos_max } => {
            let Some(axis) = direction(scene, from, target) else {
                return 0.0;
            };
            if axis.dot(wi_w) >= cos_max {
                uniform_cone_pdf(cos_max)
            } else {
                0.0
            }
        }
        Extension::Cone(cone) | Extension::ConeAlong(cone) => {
            let origin = if matches!(ext, Extension::Cone(_)) {
                from
            } else {
                counterpart
            };
            let Some(axis) = direction(scene, origin, target) else {
                return 0.0;
            };
            // The angle as the ray left: from the offset origin the extension's ray had (the
            // cone's angles go down to 10⁻⁴, the offset is 10⁻⁶ across a short segment).
            let w = if is_distant(scene, to) {
                wi_w
            } else {
                let o = offset_ray_origin(from.p, from.p_error, from.ng, wi_w);
                (to.p - o).try_normalize().unwrap_or(wi_w)
            };
            return cone.pdf(axis, w)
                * if is_distant(scene, to) {
                    1.0
                } else {
                    area_jacobian(from.p, to.p, to.ng) as f64
                };
        }
    };
    let jacobian = if is_distant(scene, to) {
        1.0
    } else {
        area_jacobian(from.p, to.p, to.ng)
    };
    p_omega as f64 * jacobian as f64
}

/// Sum of the smooth components' weights.
fn smooth_weight(bsdf: &Bsdf) -> f32 {
    bsdf.components()
        .filter(|(c, _)| !c.is_delta())
        .map(|(_, w)| w)
        .sum()
}

/// Density of the smooth part of the BSDF, renormalised: what [`sample_smooth`] draws from.
fn smooth_pdf(bsdf: &Bsdf, wo: Vec3, wi: Vec3) -> f32 {
    let w = smooth_weight(bsdf);
    if w > 0.0 {
        bsdf.pdf(wo, wi) / w
    } else {
        0.0
    }
}

/// Samples a direction from the smooth components (chosen by weight); local frame. Its
/// density is [`smooth_pdf`].
fn sample_smooth(bsdf: &Bsdf, wo: Vec3, rng: &mut Rng) -> Option<Vec3> {
    let total = smooth_weight(bsdf);
    if total <= 0.0 {
        return None;
    }
    let mut u = rng.uniform() * total;
    let (mut chosen, mut last) = (None, None);
    for (c, w) in bsdf.components().filter(|(c, _)| !c.is_delta()) {
        last = Some(c);
        if u < w {
            chosen = Some(c);
            break;
        }
        u -= w;
    }
    let c = chosen.or(last)?;
    let s = c.sample_with(wo, rng.uniform(), rng.uniform2())?;
    (smooth_pdf(bsdf, wo, s.wi) > 0.0).then_some(s.wi)
}

/// Checks that `hit` can stand in for `original` (same weak type) and builds the vertex.
/// `prev` is the vertex the ray came from.
fn matching_vertex(
    scene: &Scene,
    hit: &SurfaceHit,
    original: &PathVertex,
    prev: Vec3,
) -> Option<PathVertex> {
    let kind = WeakNode::of(original);
    if kind == WeakNode::Light {
        // Only an area light can be hit, and only an area light may replace one: a point
        // light's vertex is never moved (and paths on it are in another measure).
        let i = usize::try_from(hit.emitter).ok()?;
        let original_area =
            usize::try_from(original.emitter).is_ok_and(|o| o < scene.lights.emitters.len());
        if !original_area || i >= scene.lights.emitters.len() {
            return None;
        }
        let towards = (prev - hit.p).try_normalize()?;
        return (!scene.lights.emitted(i, hit.p, towards).is_black())
            .then(|| PathVertex::from_hit(hit, NodeType::Light, 0));
    }
    scene.materials.get(hit.material as usize)?;
    let bsdf = scene.bsdf(hit);
    match kind {
        WeakNode::Smooth => bsdf
            .has_non_delta()
            .then(|| PathVertex::from_hit(hit, original.node, original.component)),
        WeakNode::DiracReflection | WeakNode::DiracTransmission => {
            let wo = Frame::from_z(hit.ns).to_local((prev - hit.p).try_normalize()?);
            let (c, _, _) = dirac_component(&bsdf, wo, kind == WeakNode::DiracTransmission)?;
            Some(PathVertex::from_hit(hit, original.node, c as u8))
        }
        WeakNode::Eye | WeakNode::Light => None,
    }
}

/// Traces `ray`, leaving the vertex at `from`, to the vertex that stands in for `original`: a
/// hit [`matching_vertex`] accepts or, when `original` is the environment, an escape along a
/// direction the environment shines from (a directional light cannot be reached by a ray).
pub(crate) fn trace_vertex(
    scene: &Scene,
    tracer: &Tracer,
    ray: &Ray,
    from: Vec3,
    original: &PathVertex,
) -> Option<PathVertex> {
    if is_distant(scene, original) {
        let i = light_index(scene, original)?;
        if scene.lights.kind(i) != LightKind::Environment || tracer.intersect(ray).is_some() {
            return None;
        }
        let dir = ray.dir.try_normalize()?;
        return (!scene.lights.environment_radiance(dir).is_black())
            .then(|| distant_vertex(from, dir, i));
    }
    let hit = tracer.intersect(ray)?;
    matching_vertex(scene, &hit, original, from)
}

/// Image size film-plane migration is clipped to.
fn film_size(scene: &Scene) -> (u32, u32) {
    (scene.camera.width, scene.camera.height)
}

const MISS: Proposal = Proposal::Miss;

/// Builds a proposal `y` from `x` under `policy`. Returns the proposal's validity and its
/// transition ratio T(y→x)/T(x→y), computed from the densities the sampling routines
/// reported (forward) and evaluated (reverse).
pub fn propose(
    scene: &Scene,
    tracer: &Tracer,
    rng: &mut Rng,
    policy: &Policy,
    x: &Path,
    y: &mut Path,
) -> Proposal {
    propose_with(scene, tracer, rng, policy, FilmMove::Window, x, y)
}

/// [`propose`] with the raster position moved by `film` instead of film-plane migration
/// (a [`FilmMove`] or a plugin's own symmetric [`RasterMove`]).
pub fn propose_with(
    scene: &Scene,
    tracer: &Tracer,
    rng: &mut Rng,
    policy: &Policy,
    film: impl RasterMove,
    x: &Path,
    y: &mut Path,
) -> Proposal {
    let xv = x.vertices();
    if xv.len() < 2 {
        return MISS;
    }
    let chains = Chains::of(scene, policy, xv);
    let n = xv.len() - 1;
    let (w, h) = film_size(scene);
    let Some(raster) = film.sample(x, w, h, rng) else {
        return MISS;
    };
    y.raster = raster;
    y.film_window = x.film_window;
    y.contribution = x.contribution;
    // The eye vertex moves with the raster position on an orthographic film; a lens point is
    // kept (`flowlight_core::thin_lens`, "Markov chains").
    let eye_ray = scene.camera.ray_from_eye(y.raster, xv[0].p);
    y.vertices[0] = PathVertex::eye(eye_ray.origin, scene.camera.forward);
    let Some((mut jx, mut jy)) =
        trace_chain(scene, tracer, chains, eye_ray, eye_ray.origin, xv, 1, y, 1)
    else {
        return MISS;
    };
    let (mut fwd, mut rev) = (1.0f64, 1.0f64);
    let mut extensions = 0u32;
    while jx < n {
        let Some(step) = step(
            scene, tracer, rng, policy, chains, xv, y, jx, jy, extensions,
        ) else {
            return MISS;
        };
        fwd *= step.fwd;
        rev *= step.rev;
        (jx, jy) = (step.jx, step.jy);
        extensions += 1;
    }
    y.vertex_count = (jy + 1) as u32;
    match chains {
        // Same types, same layer.
        Chains::Fixed => {
            y.layer = x.layer;
            // Free chain lengths keep both ends of a move of one kind (module docs).
            if policy.free_chains && all_forced(scene, y.vertices()) {
                return MISS;
            }
        }
        Chains::Free => y.layer = lighting_layer(y.vertices()),
    }
    finish(fwd, rev)
}

/// The proposal's validity and transition ratio from its forward and reverse densities.
fn finish(fwd: f64, rev: f64) -> Proposal {
    let ratio = rev / fwd;
    if !(ratio.is_finite() && ratio >= 0.0) {
        // A valid path with a degenerate density: reported, and rejected by the integrator.
        return Proposal::Move {
            transition_ratio: f32::NAN,
        };
    }
    Proposal::Move {
        transition_ratio: ratio as f32,
    }
}

/// How the engine follows a chain of Dirac vertices (module docs). One engine walks x and y
/// with an index each; with fixed chains the two indices stay equal.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Chains {
    /// Veach's rule: vertex by vertex, each of x's weak type, so y keeps x's length.
    Fixed,
    /// Through forced Dirac vertices as far as they go ("Dirac chains of any length").
    Free,
}

impl Chains {
    /// The rule for a move from (or to) the path `v`. Recomputed on every call rather than
    /// cached with the chain's state (which would take a flag in the plugin ABI's `Path`):
    /// [`all_forced`] measured 0.9% of the mirror chain's ERPT render and 0.15% of the glass
    /// caustic's (perf, self time, 2026-12-03).
    fn of(scene: &Scene, policy: &Policy, v: &[PathVertex]) -> Chains {
        if policy.free_chains && all_forced(scene, v) {
            Chains::Free
        } else {
            Chains::Fixed
        }
    }
}

/// Follows `ray`, leaving y's vertex at `from`, through the chain that stands in for x's
/// chain from `xv[sx]` on (its Dirac vertices and the vertex that ends it), storing it in `y`
/// from index `sy` on. Returns the indices, in x and in y, of the vertex that ends the two
/// chains; `None`: a domain miss.
#[allow(clippy::too_many_arguments)]
fn trace_chain(
    scene: &Scene,
    tracer: &Tracer,
    chains: Chains,
    ray: Ray,
    from: Vec3,
    xv: &[PathVertex],
    sx: usize,
    y: &mut Path,
    sy: usize,
) -> Option<(usize, usize)> {
    let mx = chain_end(xv, sx);
    if chains == Chains::Free {
        return Some((
            mx,
            trace_free_chain(scene, tracer, ray, from, &xv[mx], y, sy)?,
        ));
    }
    debug_assert_eq!(sx, sy, "fixed chains keep x's indices");
    let mut j = sx;
    y.vertices[j] = trace_vertex(scene, tracer, &ray, from, &xv[j])?;
    while j < mx {
        // y_j has x_j's Dirac type: follow its lobe.
        let yj = y.vertices[j];
        let frame = Frame::from_z(yj.ns);
        let wo_w = (y.vertices[j - 1].p - yj.p).try_normalize()?;
        let wo = frame.to_local(wo_w);
        if !side_consistent(yj.ng, wo_w, wo) {
            return None;
        }
        let bsdf = vertex_bsdf(scene, &yj)?;
        let (c, _) = bsdf.components().nth(yj.component as usize)?;
        let transmission = WeakNode::of(&xv[j]) == WeakNode::DiracTransmission;
        let (wi, _) = dirac_scatter(&c, wo, transmission)?;
        let ray = yj.surface().spawn_ray(frame.to_world(wi));
        y.vertices[j + 1] = trace_vertex(scene, tracer, &ray, yj.p, &xv[j + 1])?;
        j += 1;
    }
    Some((mx, mx))
}

/// Follows `ray`, leaving the vertex at `from`, through forced Dirac vertices (stored in `y`
/// from index `at` on) to the first other vertex, which must stand in for `end` as
/// [`trace_vertex`] decides; returns that vertex's index in `y` (module docs, "Dirac chains of
/// any length"). `None`: a domain miss (another end, a leak, no room in the path).
fn trace_free_chain(
    scene: &Scene,
    tracer: &Tracer,
    mut ray: Ray,
    mut from: Vec3,
    end: &PathVertex,
    y: &mut Path,
    mut at: usize,
) -> Option<usize> {
    loop {
        if at >= MAX_PATH_VERTICES {
            return None;
        }
        let Some(hit) = tracer.intersect(&ray) else {
            // Only the environment ends a chain that escapes.
            let i = light_index(scene, end).filter(|_| is_distant(scene, end))?;
            if scene.lights.kind(i) != LightKind::Environment {
                return None;
            }
            let dir = ray.dir.try_normalize()?;
            if scene.lights.environment_radiance(dir).is_black() {
                return None;
            }
            y.vertices[at] = distant_vertex(from, dir, i);
            return Some(at);
        };
        let lobe = (hit.emitter < 0)
            .then(|| scene.materials.get(hit.material as usize))
            .flatten()
            .and_then(|_| {
                let wo = Frame::from_z(hit.ns).to_local((from - hit.p).try_normalize()?);
                let bsdf = scene.bsdf(&hit);
                let (c, transmission) = forced_lobe(&bsdf, wo)?;
                Some((bsdf.component(c), c, transmission, wo))
            });
        let Some((component, c, transmission, wo)) = lobe else {
            if is_distant(scene, end) {
                return None;
            }
            y.vertices[at] = matching_vertex(scene, &hit, end, from)?;
            return Some(at);
        };
        let node = if transmission {
            NodeType::SpecularTransmission
        } else {
            NodeType::SpecularReflection
        };
        let v = PathVertex::from_hit(&hit, node, c as u8);
        let frame = Frame::from_z(v.ns);
        if !side_consistent(v.ng, frame.to_world(wo), wo) {
            return None;
        }
        let (wi, _) = dirac_scatter(&component, wo, transmission)?;
        let w = frame.to_world(wi);
        if !side_consistent(v.ng, w, wi) {
            return None;
        }
        y.vertices[at] = v;
        at += 1;
        ray = v.surface().spawn_ray(w);
        from = v.p;
    }
}

/// One step of [`propose_with`] at the smooth vertex y[jy] standing in for x[jx]: the
/// indices (in x, in y) of the vertex it got to and the step's forward and reverse
/// densities.
struct Step {
    jx: usize,
    jy: usize,
    fwd: f64,
    rev: f64,
}

/// Reconnects y[jy] to x[jx + 1] (keeping x's vertices after it, shifted) or extends it and
/// follows the new direction's chain ([`trace_chain`]).
#[allow(clippy::too_many_arguments)]
fn step(
    scene: &Scene,
    tracer: &Tracer,
    rng: &mut Rng,
    policy: &Policy,
    chains: Chains,
    xv: &[PathVertex],
    y: &mut Path,
    jx: usize,
    jy: usize,
    extensions: u32,
) -> Option<Step> {
    let n = xv.len() - 1;
    let yj = y.vertices[jy];
    let frame = Frame::from_z(yj.ns);
    let wo_w = (y.vertices[jy - 1].p - yj.p).try_normalize()?;
    let wo = frame.to_local(wo_w);
    if !side_consistent(yj.ng, wo_w, wo) {
        return None;
    }
    let p_r = p_reconnect(scene, policy, xv, jx, extensions);
    if p_r > 0.0 && rng.uniform() < p_r {
        let target = &xv[jx + 1];
        let distant = is_distant(scene, target);
        let dir = direction(scene, &yj, target)?;
        if !side_consistent(yj.ng, dir, frame.to_local(dir)) {
            return None;
        }
        let tail = n - jx;
        if jy + tail >= MAX_PATH_VERTICES {
            return None;
        }
        let shadow = if distant {
            yj.surface().spawn_ray(dir)
        } else {
            yj.surface()
                .spawn_ray_to(target.p, target.p_error, target.ng)
        };
        if tracer.occluded(&shadow) {
            return None;
        }
        y.vertices[jy + 1..=jy + tail].copy_from_slice(&xv[jx + 1..=n]);
        if distant {
            // The same direction, its nominal point moved with y's last smooth vertex.
            y.vertices[jy + tail].p = yj.p + dir;
        }
        let p = p_r as f64;
        return Some(Step {
            jx: n,
            jy: jy + tail,
            fwd: p,
            rev: p,
        });
    }
    let ext = policy.extension?;
    let dir = match ext {
        Extension::Bsdf => {
            let bsdf = vertex_bsdf(scene, &yj)?;
            frame.to_world(sample_smooth(&bsdf, wo, rng)?)
        }
        Extension::Cap { cos_max } => {
            let axis = direction(scene, &yj, &xv[jx + 1])?;
            Frame::from_z(axis).to_world(uniform_cone(rng.uniform2(), cos_max))
        }
        Extension::Cone(cone) => cone.sample(direction(scene, &yj, &xv[jx + 1])?, rng),
        Extension::ConeAlong(cone) => cone.sample(direction(scene, &xv[jx], &xv[jx + 1])?, rng),
    };
    if !side_consistent(yj.ng, dir, frame.to_local(dir)) {
        return None;
    }
    let ray = yj.surface().spawn_ray(dir);
    let (mx, my) = trace_chain(scene, tracer, chains, ray, yj.p, xv, jx + 1, y, jy + 1)?;
    // Densities are evaluated from the vertex positions, in the forward as in the reverse
    // direction and in `density`: the sampled direction and the one the positions give
    // differ by the ray-origin offset, which matters for close, grazing vertices.
    let q = (1.0 - p_r) as f64;
    let yv = &y.vertices;
    Some(Step {
        jx: mx,
        jy: my,
        fwd: q * extension_density(
            scene,
            ext,
            &yv[jy - 1],
            &yj,
            &yv[jy + 1],
            &xv[jx],
            &xv[jx + 1],
        ),
        rev: q * extension_density(
            scene,
            ext,
            &xv[jx - 1],
            &xv[jx],
            &xv[jx + 1],
            &yj,
            &yv[jy + 1],
        ),
    })
}

/// Transition density T(x → y) of `policy`, evaluated from the two paths alone (film term in
/// raster measure, vertices in the target function's measure). 0 when `policy` cannot turn
/// `x` into `y`.
pub fn density(scene: &Scene, policy: &Policy, x: &Path, y: &Path) -> f64 {
    density_with(scene, policy, FilmMove::Window, x, y)
}

/// [`density`] with the raster position moved by `film`: the steps of [`propose_with`] read
/// back from the two paths.
pub fn density_with(
    scene: &Scene,
    policy: &Policy,
    film: impl RasterMove,
    x: &Path,
    y: &Path,
) -> f64 {
    let (xv, yv) = (x.vertices(), y.vertices());
    if xv.len() < 2 || yv.len() < 2 || x.film_window != y.film_window {
        return 0.0;
    }
    // A move and its reverse follow one rule (module docs).
    let chains = Chains::of(scene, policy, xv);
    if Chains::of(scene, policy, yv) != chains {
        return 0.0;
    }
    // Proposals keep the lens point (`flowlight_core::thin_lens`, "Markov chains").
    if scene.camera.has_lens() && xv[0].p != yv[0].p {
        return 0.0;
    }
    if chains == Chains::Fixed
        && (xv.len() != yv.len()
            || xv
                .iter()
                .zip(yv)
                .any(|(a, b)| WeakNode::of(a) != WeakNode::of(b)))
    {
        return 0.0;
    }
    let (nx, ny) = (xv.len() - 1, yv.len() - 1);
    let (w, h) = film_size(scene);
    let mut d = film.density(x, y, w, h);
    let (mut jx, mut jy) = (chain_end(xv, 1), chain_end(yv, 1));
    if on_caustic_leaf(scene, xv, yv, jx, jy, 0) {
        return 0.0;
    }
    let mut extensions = 0u32;
    loop {
        if d == 0.0 || WeakNode::of(&xv[jx]) != WeakNode::of(&yv[jy]) {
            return 0.0;
        }
        if jx == nx || jy == ny {
            return if jx == nx && jy == ny { d } else { 0.0 };
        }
        let p_r = p_reconnect(scene, policy, xv, jx, extensions);
        if nx - jx == ny - jy
            && yv[jy + 1..]
                .iter()
                .zip(&xv[jx + 1..])
                .all(|(a, b)| same_vertex(scene, a, b))
        {
            return d * p_r as f64;
        }
        let Some(ext) = policy.extension else {
            return 0.0;
        };
        d *= (1.0 - p_r) as f64
            * extension_density(
                scene,
                ext,
                &yv[jy - 1],
                &yv[jy],
                &yv[jy + 1],
                &xv[jx],
                &xv[jx + 1],
            );
        let (mx, my) = (chain_end(xv, jx + 1), chain_end(yv, jy + 1));
        if on_caustic_leaf(scene, xv, yv, mx, my, jy) {
            return 0.0;
        }
        extensions += 1;
        (jx, jy) = (mx, my);
    }
}

/// Whether y's chain after its vertex `sy`, ending at y[my], moved its Dirac vertices yet
/// ends on x's vertex x[mx]: a point traced after a moved Dirac vertex lands there with
/// probability 0, so such a y lies on a leaf of the caustic perturbation
/// ([`crate::specular_chain`]), which this engine gives no density.
fn on_caustic_leaf(
    scene: &Scene,
    xv: &[PathVertex],
    yv: &[PathVertex],
    mx: usize,
    my: usize,
    sy: usize,
) -> bool {
    my > sy + 1
        && !same_vertex(scene, &yv[my - 1], &xv[mx - 1])
        && !is_distant(scene, &xv[mx])
        && same_vertex(scene, &yv[my], &xv[mx])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testscene::*;
    use std::f64::consts::PI;

    const BLOW: Policy = Policy {
        min_extensions: 0,
        p_reconnect: 0.5,
        extension: Some(Extension::Bsdf),
        drill_caustics: false,
        free_chains: false,
    };

    fn soft(cap_degrees: f32) -> Policy {
        Policy {
            min_extensions: 1,
            p_reconnect: 1.0,
            extension: Some(Extension::cap_degrees(cap_degrees)),
            drill_caustics: false,
            free_chains: false,
        }
    }

    /// Film density of the migration the tests make: 1/K² with K = 8.
    const FILM: f64 = 1.0 / 64.0;

    fn moved(p: &Path) -> Path {
        let mut q = *p;
        q.raster += glam::Vec2::new(1.0, -0.5);
        q
    }

    #[test]
    fn a_dirac_light_is_always_reconnected_to_whatever_the_policy() {
        let scene = scene();
        let (x1, y1) = (
            floor(Vec3::new(0.2, 0.0, -0.5)),
            floor(Vec3::new(0.3, 0.0, -0.6)),
        );
        let x = path(&[eye(), x1, sun(x1.p)], 8);
        for policy in [BLOW, soft(5.0)] {
            assert_eq!(p_reconnect(&scene, &policy, x.vertices(), 1, 0), 1.0);
        }
        // y: x1 moved, the sun's vertex kept (its nominal point moves with y1).
        let mut y = moved(&path(&[eye(), y1, sun(y1.p)], 8));
        for policy in [BLOW, soft(5.0)] {
            assert!((density(&scene, &policy, &x, &y) - FILM).abs() < 1e-12);
        }
        // A sun vertex in another direction cannot be reached at all.
        y.vertices[2] = distant_vertex(y1.p, Vec3::Y, SUN_INDEX);
        assert_eq!(density(&scene, &BLOW, &x, &y), 0.0);
        // An environment or area light keeps the policy's probability.
        let x = path(&[eye(), x1, sky(x1.p, Vec3::Y)], 8);
        assert_eq!(p_reconnect(&scene, &BLOW, x.vertices(), 1, 0), 0.5);
        assert_eq!(p_reconnect(&scene, &soft(5.0), x.vertices(), 1, 0), 0.0);
    }

    #[test]
    fn a_sky_direction_is_extended_to_in_solid_angle_and_reconnected_to_as_it_is() {
        let scene = scene();
        let (x1, y1) = (
            floor(Vec3::new(0.2, 0.0, -0.5)),
            floor(Vec3::new(0.3, 0.0, -0.6)),
        );
        let w_x = Vec3::new(0.1, 1.0, 0.05).normalize();
        let x = path(&[eye(), x1, sky(x1.p, w_x)], 8);
        // Hard reconnection to the same direction: T = film · p_r.
        let kept = moved(&path(&[eye(), y1, sky(y1.p, w_x)], 8));
        assert!((density(&scene, &BLOW, &x, &kept) - FILM * 0.5).abs() < 1e-12);
        // BSDF extension to a new direction: film · (1 − p_r) · cos θ/π, no area Jacobian.
        let w_y = Vec3::new(-0.4, 0.8, 0.3).normalize();
        let ext = moved(&path(&[eye(), y1, sky(y1.p, w_y)], 8));
        let want = FILM * 0.5 * w_y.y as f64 / PI;
        let got = density(&scene, &BLOW, &x, &ext);
        assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
        // Cap extension: uniform in the cap around x's direction, 0 outside it.
        let cap = soft(30.0);
        let want = FILM / (2.0 * PI * (1.0 - 30f64.to_radians().cos()));
        let near = Vec3::new(0.3, 1.0, 0.0).normalize(); // 11° from w_x
        let inside = moved(&path(&[eye(), y1, sky(y1.p, near)], 8));
        let got = density(&scene, &cap, &x, &inside);
        assert!((got / want - 1.0).abs() < 1e-4, "{got} vs {want}");
        assert_eq!(density(&scene, &cap, &x, &ext), 0.0);
    }

    #[test]
    fn extension_density_to_an_area_light_has_the_area_jacobian() {
        let scene = scene();
        let (e, x1) = (eye(), floor(Vec3::new(0.2, 0.0, -0.5)));
        let l = lamp(Vec3::new(0.1, 2.0, -0.2));
        let d = l.p - x1.p;
        let cos = (d.y / d.length()) as f64;
        let want = cos / PI * cos / d.length_squared() as f64;
        let got = extension_density(&scene, Extension::Bsdf, &e, &x1, &l, &x1, &l);
        assert!((got / want - 1.0).abs() < 1e-5, "{got} vs {want}");
        let s = sky(x1.p, d);
        let got = extension_density(&scene, Extension::Bsdf, &e, &x1, &s, &x1, &s);
        assert!((got / (cos / PI) - 1.0).abs() < 1e-5, "{got}");
    }
}
