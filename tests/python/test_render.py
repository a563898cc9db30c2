"""Rendering from Python: the same pixels as the command line, many renders over one load,
configs given as dicts, results, progress and interruption."""

from __future__ import annotations

import os
import re
import signal
import threading
import tomllib
from pathlib import Path

import numpy as np
import pytest

import flowlight
from conftest import CORNELL, ROOT, run_cli


def test_cornell_box_equals_the_cli_bit_for_bit(cli, tmp_path):
    img = flowlight.load(CORNELL).render(spp=4, seed=11, progress=False)
    out = tmp_path / "cli.exr"
    proc = run_cli(cli, "render", str(CORNELL), "--spp", "4", "--seed", "11", "--out", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    ref = flowlight.read_exr(out)
    assert img.rgb.shape == (512, 512, 3) and img.rgb.dtype == np.float32
    assert img.rgb.mean() > 0.01
    assert np.array_equal(img.rgb, ref["rgb"]), np.abs(img.rgb - ref["rgb"]).max()
    # The EXR Python writes holds the same pixels and the command line's header.
    saved = img.save(tmp_path / "py.exr")
    assert saved[0] == tmp_path / "py.exr"
    again = flowlight.read_exr(tmp_path / "py.exr")
    assert np.array_equal(again["rgb"], ref["rgb"])
    header = lambda r: {k: v for k, v in r["metadata"].items() if k != "flowlight.reference.from"}
    assert header(again) == header(ref) and len(header(ref)) > 10
    assert img.metadata["flowlight.seed"] == "11"
    assert not img.partial


def test_a_sweep_of_8_renders_loads_the_scene_once():
    before = flowlight.loads_so_far()
    scene = flowlight.load(CORNELL)
    images = [
        scene.render(spp=1, seed=3, set={"path_depth": depth}, progress=False) for depth in range(1, 9)
    ]
    assert flowlight.loads_so_far() - before == 1
    assert {img.stats["load_id"] for img in images} == {scene.load_id}
    assert [img.stats["render_index"] for img in images] == list(range(1, 9))
    assert {img.stats["load_seconds"] for img in images} == {scene.load_seconds}
    assert scene.renders == 8
    # The parameter took effect: deeper paths bring more light.
    means = [float(img.rgb.mean()) for img in images]
    assert means[0] < means[2] < means[7], means
    assert "path_depth=8" in images[7].metadata["flowlight.params"]


def test_a_dict_with_the_files_keys_renders_as_the_file():
    table = tomllib.loads(CORNELL.read_text())
    from_dict = flowlight.load(table, base_dir=CORNELL.parent).render(spp=2, progress=False)
    from_file = flowlight.load(CORNELL).render(spp=2, progress=False)
    assert np.array_equal(from_dict.rgb, from_file.rgb)


def test_the_configs_aovs_come_back_as_layers(cli, tmp_path):
    table = tomllib.loads(CORNELL.read_text())
    table.setdefault("output", {})["aovs"] = ["albedo", "depth", "object_id"]
    img = flowlight.load(table, base_dir=CORNELL.parent).render(spp=2, progress=False)
    h, w, _ = img.rgb.shape
    for name in ("albedo", "depth", "object_id"):
        assert img.layers[name].shape == (h, w, 3), name
    # Nearly every camera ray hits the box (a miss reads 0): depth ≥ 0, an albedo in [0, 1].
    depth = img.layers["depth"]
    assert (depth >= 0).all() and (depth > 0).mean() > 0.9
    albedo = img.layers["albedo"]
    assert (albedo >= 0).all() and (albedo <= 1).all() and albedo.mean() > 0.1
    # The same pass as the command line's, layer for layer.
    cfg = tmp_path / "aovs.toml"
    cfg.write_text(CORNELL.read_text().replace("[output]\n", '[output]\naovs = ["albedo", "depth", "object_id"]\n', 1)
                   .replace('scene = "cornell-box.gltf"', f'scene = "{CORNELL.parent / "cornell-box.gltf"}"'))
    out = tmp_path / "cli.exr"
    proc = run_cli(cli, "render", str(cfg), "--spp", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    exr = flowlight.read_exr(out)
    for name in ("albedo", "depth"):
        assert np.array_equal(exr["layers"][name], img.layers[name]), name


def test_denoise_adds_the_clis_denoised_layer_and_keeps_the_beauty(cli, tmp_path):
    cfg = tmp_path / "small.toml"
    cfg.write_text(CORNELL.read_text().replace("width = 512", "width = 96").replace("height = 512", "height = 96")
                   .replace('scene = "cornell-box.gltf"', f'scene = "{CORNELL.parent / "cornell-box.gltf"}"'))
    out = tmp_path / "cli.exr"
    proc = run_cli(cli, "render", str(cfg), "--spp", "4", "--seed", "5", "--denoise", "--out", str(out))
    if proc.returncode != 0 and "Open Image Denoise" in proc.stderr:
        with pytest.raises(flowlight.RenderError, match="Open Image Denoise"):
            flowlight.load(cfg).render(spp=4, seed=5, denoise=True, progress=False)
        pytest.skip("Open Image Denoise is not available: " + proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    scene = flowlight.load(cfg)
    img = scene.render(spp=4, seed=5, denoise=True, progress=False)
    plain = scene.render(spp=4, seed=5, progress=False)
    assert np.array_equal(img.rgb, plain.rgb), "denoising changed the beauty"
    assert "denoised" not in plain.layers
    exr = flowlight.read_exr(out)
    for name in ("albedo", "normal"):
        assert np.array_equal(exr["layers"][name], img.layers[name]), name
    # The same filter over the same inputs as the command line's.
    denoised = img.layers["denoised"]
    assert denoised.shape == img.rgb.shape
    assert np.allclose(denoised, exr["layers"]["denoised"], rtol=1e-4, atol=1e-5)
    # It filtered: far smoother than the 4-spp beauty, about as bright.
    rough = lambda a: float(np.abs(np.diff(a[40:70, 20:76].mean(2), axis=1)).mean())
    assert rough(denoised) < 0.5 * rough(img.rgb), (rough(denoised), rough(img.rgb))
    assert abs(float(denoised.mean()) / float(img.rgb.mean()) - 1) < 0.05
    assert img.metadata["flowlight.denoiser"].startswith("Open Image Denoise")


def test_a_bad_key_raises_the_clis_message(cli, tmp_path):
    # An integrator parameter MCPT does not have, through set= and --set.
    scene = flowlight.load(CORNELL)
    with pytest.raises(flowlight.PluginError) as err:
        scene.render(spp=1, set={"no_such_key": 3}, progress=False)
    proc = run_cli(cli, "render", str(CORNELL), "--spp", "1", "--set", "no_such_key=3", "--out", str(tmp_path / "x.exr"))
    from conftest import cli_error

    # The same line, but for where the plugin was found (the package's folder, the CLI's).
    plugin_file = re.compile(r"\(/[^()]*/libflowlight_mcpt\.so\)")
    assert plugin_file.sub("(mcpt)", str(err.value)) == plugin_file.sub("(mcpt)", cli_error(proc))
    assert "\n" not in str(err.value) and "no_such_key" in str(err.value)
    # A key the config format does not have, in a file.
    bad = tmp_path / "bad.toml"
    bad.write_text(CORNELL.read_text().replace("[render]\n", "[render]\nwidht = 3\n").replace(
        'scene = "cornell-box.gltf"', f'scene = "{CORNELL.parent / "cornell-box.gltf"}"'))
    with pytest.raises(flowlight.ConfigError) as err:
        flowlight.load(bad)
    assert str(err.value) == cli_error(run_cli(cli, "render", str(bad)))
    assert isinstance(err.value, flowlight.Error)


def test_keyboard_interrupt_in_the_progress_callback_returns_a_partial_image():
    scene = flowlight.load(CORNELL)
    calls = []

    def interrupt(p):
        calls.append(p)
        raise KeyboardInterrupt

    img = scene.render(spp=100000, seed=1, progress=interrupt)
    assert len(calls) == 1
    assert img.partial and img.stats["interrupted"]
    assert 0 < img.stats["spp"] < 100000
    assert img.metadata["flowlight.interrupted"] == "true"
    assert img.rgb.mean() > 0


def test_ctrl_c_returns_a_partial_image():
    scene = flowlight.load(CORNELL)
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        img = scene.render(spp=100000, progress=False)
    finally:
        timer.cancel()
    assert img.partial and 0 < img.stats["spp"] < 100000


def test_other_exceptions_of_the_callback_stop_and_propagate():
    scene = flowlight.load(CORNELL)

    def fail(p):
        raise ValueError("stop here")

    with pytest.raises(ValueError, match="stop here"):
        scene.render(spp=100000, progress=fail)


def test_progress_reports_fractions_and_spp():
    seen = []
    flowlight.load(CORNELL).render(spp=64, threads=1, progress=seen.append)
    assert seen, "no progress was reported"
    assert all(0.0 <= p["fraction"] <= 1.0 for p in seen)
    assert seen[-1]["spp"] >= seen[0]["spp"] > 0


def test_results_layers_stats_and_preview():
    img = flowlight.load(ROOT / "scenes" / "glass-caustic" / "erpt.toml").render(time=0.5, progress=False)
    assert img.stats["integrator"] == "erpt" and img.stats["counters"], img.stats
    assert all(a.shape == img.rgb.shape for a in img.layers.values())
    png = img._repr_png_()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_compare_plugins_and_bad_budgets(tmp_path):
    scene = flowlight.load(CORNELL)
    a = scene.render(spp=2, seed=1, progress=False)
    b = scene.render(spp=2, seed=2, progress=False)
    same = flowlight.compare(a, a)
    assert same["relmse"] == 0.0 and same["luminance_ratio"] == 1.0
    diff = flowlight.compare(a, (b, b))
    assert diff["relmse"] > 0 and diff["reference_floor"] == 0.0
    halves = flowlight.compare(a, (a, b))
    assert halves["reference_floor"] > 0
    assert halves["relmse_corrected"] == pytest.approx(halves["relmse"] - halves["reference_floor"])
    names = {p["name"] for p in flowlight.plugins() if "name" in p}
    assert {"mcpt", "erpt", "multichain-perturbation"} <= names
    with pytest.raises(flowlight.ConfigError, match="--spp must be at least 1"):
        scene.render(spp=0)
    with pytest.raises(flowlight.ConfigError, match="--time must be a positive"):
        scene.render(time=-1.0)


def test_the_gil_is_released_while_rendering():
    scene = flowlight.load(CORNELL)
    ticks = []
    done = threading.Event()

    def count():
        while not done.is_set():
            ticks.append(1)
            done.wait(0.01)

    t = threading.Thread(target=count)
    t.start()
    try:
        img = scene.render(spp=8, threads=1, progress=False)
    finally:
        done.set()
        t.join()
    # A Python thread ran all along the render (about 100 ticks a second).
    assert len(ticks) > 10 * img.stats["wall_seconds"], (len(ticks), img.stats["wall_seconds"])


def test_bench_reads_its_suite_and_refuses_a_missing_one(tmp_path):
    with pytest.raises(flowlight.ConfigError, match="no-such-suite.toml: cannot read"):
        flowlight.bench(tmp_path / "no-such-suite.toml")
    with pytest.raises(flowlight.ConfigError, match="--budgets must be positive seconds"):
        flowlight.bench(tmp_path / "no-such-suite.toml", budgets=[0.0])
