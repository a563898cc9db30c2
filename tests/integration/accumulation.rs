//! The accumulation styles on real renders (thesis §5.9): every style, thread count and cache
//! size gives the same bits in exact precision, for ERPT (flanged, with and without lighting
//! layers) and MCPT; f32 precision agrees to rounding; the host's choice and the config's
//! errors.

use crate::common;

use flowlight_host::accumulation::{Frame, MicroTileCache, Precision, Style};
use flowlight_host::error::{HostError, PartRefusal};
use flowlight_host::renderer::{Overrides, Renderer};
use flowlight_scene::ConfigError;
use std::sync::atomic::AtomicBool;

fn erpt(size: u32, layers: bool) -> Renderer {
    common::renderer_at(
        "cornell-box/erpt.toml",
        size,
        size,
        2,
        &[
            ("layers", toml::Value::Boolean(layers)),
            ("mutations_per_sample", toml::Value::Integer(8)),
        ],
    )
}

fn exact_sums(f: &Frame) -> Vec<Vec<[u128; 3]>> {
    std::iter::once(f.main_sums().to_vec())
        .chain((0..f.layer_count as usize).map(|k| f.layer_sums(k).to_vec()))
        .collect()
}

fn render_with(s: &mut Renderer, style: Option<Style>, threads: usize, cache: u64) -> Frame {
    s.options.accumulation = style;
    s.options.threads = threads;
    s.options.cache_bytes = cache;
    let out = common::render(s);
    let a = out
        .stats
        .accumulation
        .expect("a render reports its accumulation");
    if let Some(style) = style {
        assert_eq!(a.style, style);
    }
    out.frame
}

#[test]
fn erpt_gives_the_same_bits_in_every_style_thread_count_and_cache_size() {
    for layers in [false, true] {
        let mut s = erpt(40, layers);
        s.options.tile_size = 8;
        let planes = if layers {
            s.instance.info.layer_count as usize + 1
        } else {
            1
        };
        let reference = render_with(&mut s, Some(Style::Blasting), 1, 0);
        assert!(reference.image().iter().any(|p| p.r > 0.0));
        let want = exact_sums(&reference);
        let one_slot = MicroTileCache::slot_bytes(planes, Precision::Exact);
        for (style, threads, cache) in [
            (Some(Style::Blasting), 2, 0),
            (Some(Style::Buffering), 2, 0),
            (Some(Style::Caching), 1, 16 << 20),
            // One micro-tile per thread: a flush at nearly every chain step.
            (Some(Style::Caching), 2, 2 * one_slot),
            (None, 2, 3 * one_slot),
        ] {
            let frame = render_with(&mut s, style, threads, cache);
            assert!(
                exact_sums(&frame) == want,
                "{style:?}, {threads} threads, cache {cache} B, layers {layers}"
            );
            assert_eq!(frame.uniform_spp(), reference.uniform_spp());
        }
    }
}

#[test]
fn mcpt_gives_the_same_bits_in_every_style() {
    let mut s = common::renderer_at("cornell-box/cornell-box.toml", 40, 40, 3, &[]);
    s.options.tile_size = 16;
    let reference = render_with(&mut s, None, 2, 0);
    let want = exact_sums(&reference);
    for style in [Style::Buffering, Style::Caching] {
        let frame = render_with(&mut s, Some(style), 2, 1 << 20);
        assert!(exact_sums(&frame) == want, "{style:?}");
        assert_eq!(frame.samples(), reference.samples());
    }
}

/// A tile-local integrator's passes (1, 2, 4, 8, 16, … samples) run as one round whose
/// units the threads take in pass order (render.rs): a thread that finishes the last unit of
/// a pass it can take goes on to the next pass instead of waiting for the pass's slowest
/// tile. The first unit to finish holds its thread until another thread has finished a unit
/// of a later pass; with a barrier between passes that never happens (the bounded wait then
/// fails the test instead of hanging it). The accounting and the bits are those of the
/// pass-by-pass schedule: 40 spp are passes of 1, 2, 4, 8, 16 and 9 samples, every pixel has
/// all 40, and one thread gives the same exact sums.
#[test]
fn mcpt_passes_run_without_a_barrier_between_them() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::{Condvar, Mutex};
    use std::time::Duration;
    let mut s = common::renderer_at("cornell-box/cornell-box.toml", 40, 40, 40, &[]);
    s.options.tile_size = 16; // 3 × 3 tiles of at most 16² pixels
    let one_thread = render_with(&mut s, None, 1, 0);
    s.options.threads = 2;
    let first_pass = 40 * 40; // pixel samples of the 1-sample pass
    let held = AtomicBool::new(false);
    // The most pixel samples any progress report has counted, and a signal on each report.
    let most = Mutex::new(0u64);
    let reported = Condvar::new();
    let overlapped = AtomicBool::new(false);
    let stop = AtomicBool::new(false);
    let out = s
        .render(&stop, &|p| {
            {
                let mut most = most.lock().unwrap();
                *most = (*most).max(p.pixel_samples);
            }
            reported.notify_all();
            if held.swap(true, Ordering::SeqCst) {
                return;
            }
            // This thread's unit is done but the thread stays in it until the other thread
            // has finished a unit beyond the first pass (or 30 s have gone by).
            let guard = most.lock().unwrap();
            let (guard, _) = reported
                .wait_timeout_while(guard, Duration::from_secs(30), |most| *most <= first_pass)
                .unwrap();
            overlapped.store(*guard > first_pass, Ordering::SeqCst);
        })
        .unwrap();
    assert!(out.error.is_none());
    assert!(
        overlapped.load(Ordering::SeqCst),
        "no unit of a later pass finished while a first-pass unit's thread was held: the passes wait for each other"
    );
    let st = &out.stats;
    assert_eq!(st.full_passes, 6);
    assert_eq!(st.units, 6 * 9);
    assert_eq!(st.pixel_samples, 40 * 40 * 40);
    assert!(out.frame.samples().iter().all(|&n| n == 40));
    assert!(exact_sums(&out.frame) == exact_sums(&one_thread));
}

/// More passes than one round holds (`PASSES_PER_ROUND`): 17,000 spp on a 2 × 2 image are
/// passes of 1, 2, 4, 8, 1061 × 16 and 9 samples, 1066 in all, in two rounds; every pass and
/// every sample is accounted for once.
#[test]
fn mcpt_passes_beyond_one_round_are_all_counted() {
    let s = common::renderer_at("cornell-box/cornell-box.toml", 2, 2, 17_000, &[]);
    const { assert!(1066 > flowlight_host::render::PASSES_PER_ROUND) };
    let out = common::render(&s);
    let st = &out.stats;
    assert_eq!(st.full_passes, 1066);
    assert_eq!(st.units, 1066);
    assert_eq!(st.pixel_samples, 4 * 17_000);
    assert!(out.frame.samples().iter().all(|&n| n == 17_000));
}

#[test]
fn the_host_chooses_blasting_for_path_tracing_and_caching_for_chains() {
    let mut s = common::renderer_at("cornell-box/cornell-box.toml", 16, 16, 1, &[]);
    let out = common::render(&s);
    assert_eq!(out.stats.accumulation.unwrap().style, Style::Blasting);
    s = erpt(16, false);
    let out = common::render(&s);
    let a = out.stats.accumulation.unwrap();
    assert_eq!(a.style, Style::Caching);
    assert!(a.private_bytes <= s.options.cache_bytes);
    assert!(a.counts.flushes > 0);
}

/// BDPT on the Cornell box at 24², 2 samples: deposits anywhere on the film.
fn bdpt_box() -> Renderer {
    common::renderer_with(
        "cornell-box/cornell-box.toml",
        Some("bdpt"),
        (24, 24),
        2,
        &[],
    )
}

#[test]
fn the_host_buffers_integrators_whose_deposits_land_anywhere() {
    // BDPT's light-tracing deposits scatter over the whole film: whole-image buffers, flushed
    // once per thread, not a micro-tile cache that thrashes. The image is the one Caching
    // gives, bit for bit.
    let mut s = bdpt_box();
    s.options.threads = 2;
    let buffered = common::render(&s);
    let a = buffered.stats.accumulation.unwrap();
    assert_eq!(a.style, Style::Buffering);
    assert!(
        (1..=2).contains(&a.counts.flushes),
        "at most one flush per thread, got {}",
        a.counts.flushes
    );
    s.options.accumulation = Some(Style::Caching);
    let cached = common::render(&s);
    assert_eq!(cached.stats.accumulation.unwrap().style, Style::Caching);
    for i in 0..24 * 24 {
        assert_eq!(
            buffered.frame.sum(0, i),
            cached.frame.sum(0, i),
            "pixel {i}"
        );
    }
}

#[test]
fn a_live_preview_sees_what_the_threads_buffer_while_rendering() {
    // Two units of BDPT, Buffering (the host's choice); the brightest image the progress
    // callback saw before the render ended.
    let mut s = bdpt_box();
    s.options.threads = 1;
    let mut brightest_seen = |flush: Option<std::time::Duration>| {
        s.options.preview_flush = flush;
        let brightest = std::sync::Mutex::new(0.0f64);
        let stop = std::sync::atomic::AtomicBool::new(false);
        let out = s
            .render(&stop, &|p| {
                if let Some(img) = p.image() {
                    let sum: f64 = img.iter().map(|c| (c.r + c.g + c.b) as f64).sum();
                    let mut b = brightest.lock().unwrap();
                    *b = b.max(sum);
                }
            })
            .unwrap();
        assert_eq!(out.stats.accumulation.unwrap().style, Style::Buffering);
        brightest.into_inner().unwrap()
    };
    assert_eq!(
        brightest_seen(None),
        0.0,
        "held until the end without a preview"
    );
    assert!(brightest_seen(Some(std::time::Duration::ZERO)) > 0.0);
}

#[test]
fn f32_precision_agrees_with_the_exact_sums_to_rounding() {
    let mut s = erpt(32, true);
    s.options.tile_size = 8;
    let exact = render_with(&mut s, Some(Style::Caching), 2, 1 << 20);
    s.options.precision = Precision::F32;
    for (style, cache) in [
        (Style::Caching, 4096 * 10),
        (Style::Blasting, 0),
        (Style::Buffering, 0),
    ] {
        let f = render_with(
            &mut s,
            Some(style),
            2,
            cache.max(2 * MicroTileCache::slot_bytes(11, Precision::F32)),
        );
        assert_eq!(f.precision(), Precision::F32);
        for k in 0..=f.layer_count as usize {
            for i in 0..(32 * 32) {
                let (a, b) = (f.sum(k, i), exact.sum(k, i));
                for c in 0..3 {
                    assert!(
                        // Exact sums truncate each deposit at 2⁻⁶⁴: absolute slack for tiny pixels.
                        (a[c] - b[c]).abs() <= 1e-5 * b[c].abs() + 1e-16,
                        "{style:?} framebuffer {k} pixel {i}: {} vs {}",
                        a[c],
                        b[c]
                    );
                }
            }
        }
        // A quarter of the exact frame's framebuffers (12 of 48 bytes a pixel), plus counts.
        assert_eq!(f.bytes(), exact.bytes() / 4 + 3 * 32 * 32);
    }
}

#[test]
fn bad_accumulation_settings_are_one_line_errors_naming_the_key() {
    let dir = common::scratch("accumulation-config");
    let cfg = dir.join("bad.toml");
    let base = common::scene_config("cornell-box/cornell-box.gltf");
    let write = |render: &str| {
        std::fs::write(
            &cfg,
            format!(
                "scene = {:?}\n[render]\nwidth = 16\nheight = 16\n{render}\n[integrator]\nplugin = \"mcpt\"\n",
                base.display().to_string()
            ),
        )
        .unwrap();
    };
    for (render, key, says) in [
        (
            "accumulation = \"pane\"",
            "render.accumulation",
            "\"caching\"",
        ),
        ("precision = \"f16\"", "render.precision", "\"exact\""),
        (
            "accumulation_cache_mib = -1.0",
            "render.accumulation_cache_mib",
            "positive",
        ),
        ("flange = \"all\"", "render.flange", "\"screen\""),
    ] {
        write(render);
        let e = Renderer::prepare(&cfg, &Overrides::default())
            .err()
            .expect(render);
        let (named, reason) = match &e {
            HostError::Config(ConfigError::Invalid { key, reason, .. }) => (key, reason),
            HostError::Config(ConfigError::Parse { key, message, .. }) => (key, message),
            e => panic!("not a config value's error: {e:?}"),
        };
        assert_eq!(named, key);
        assert!(
            reason.contains(says) && !e.to_string().contains('\n'),
            "{e}"
        );
    }
    // A cache too small for one micro-tile per thread says how much it needs.
    write("accumulation = \"caching\"\naccumulation_cache_mib = 0.0001");
    let mut s = Renderer::prepare(&cfg, &Overrides::default()).unwrap();
    s.exr_path = None;
    s.png_path = None;
    let e = s
        .render(&AtomicBool::new(false), &|_| {})
        .err()
        .expect("cache too small");
    let HostError::Render(e) = e else {
        panic!("not the render's refusal: {e:?}")
    };
    assert!(
        e.contains("render.accumulation_cache_mib") && e.contains("at least"),
        "{e}"
    );
    // `--set render.KEY=VALUE` sets the render's accumulation keys, and only those.
    write("");
    let set = |k: &str, v: toml::Value| Overrides {
        params: vec![(k.to_string(), v)],
        ..Default::default()
    };
    let s = Renderer::prepare(&cfg, &set("render.precision", "f32".into())).unwrap();
    assert_eq!(s.options.precision, Precision::F32);
    let s = Renderer::prepare(&cfg, &set("render.flange", "screen".into())).unwrap();
    assert_eq!(s.options.flange, Some(u32::MAX));
    let e = Renderer::prepare(&cfg, &set("render.width", 8.into()))
        .err()
        .unwrap();
    assert!(
        matches!(&e, HostError::NotSettable { key, .. } if key == "render.width"),
        "{e:?}"
    );
    // Distributed parts need exact sums.
    let mut s = Renderer::prepare(&cfg, &set("render.precision", "f32".into())).unwrap();
    let spec = flowlight_host::parts::PartSpec::part(0, 2, 4).unwrap();
    let e = s.set_part(spec).unwrap_err();
    assert!(
        matches!(
            e,
            HostError::Part {
                refusal: PartRefusal::NotExact,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        e.to_string().contains("render.precision = \"exact\""),
        "{e}"
    );
}
