"""The planner turns passes on and off from measurable properties of the scene."""

from pathlib import Path

import numpy as np
import pytest

from jsss.render import parse_scene, plan_scene
from jsss.render.profiles import reduction_error
from tests.jsss.render.scenes import flat_plane, scene_dict

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


def test_close_marble_sphere_needs_diffusion_and_stretch_correction():
    plan = plan_scene(parse_scene(scene_dict()), method="texture-space")
    assert plan.on("diffusion") and plan.on("stretch correction")
    assert not plan.on("layered profile")
    assert "RMS radius" in next(d.why for d in plan.decisions if d.name == "diffusion")


def test_far_away_object_is_shaded_lambert():
    scene = parse_scene(scene_dict(camera={"position": [0.0, -2.0e5, 0.0], "fov": 28, "resolution": [48, 36]}))
    plan = plan_scene(scene)
    assert plan.method == "lambert"
    assert not plan.on("diffusion") and not plan.on("stretch correction")
    why = next(d.why for d in plan.decisions if d.name == "diffusion")
    assert "Lambert" in why and "pixel footprint" in why
    assert plan.pixel_size > 4.0  # mm: wider than marble's profile


def test_plane_has_no_stretch_correction_and_no_translucent_shadows():
    plan = plan_scene(parse_scene(flat_plane({"name": "marble"})), method="texture-space")
    assert plan.on("diffusion")
    assert not plan.on("stretch correction") and not plan.on("translucent shadow maps")


def test_thin_fin_lit_from_behind_uses_translucent_shadow_maps_thick_sphere_does_not():
    fin = scene_dict(geometry={"shape": "fin", "thickness": 1.0, "segments": 16}, material={"name": "skin1"},
                     lights=[{"type": "directional", "direction": [-1.0, 0.0, 0.0]}],
                     camera={"position": [-100.0, 0.0, 0.0], "fov": 30, "resolution": [32, 32]})
    assert plan_scene(parse_scene(fin), method="texture-space").on("translucent shadow maps")
    ball = scene_dict(geometry={"shape": "sphere", "radius": 40.0}, material={"name": "ketchup"})
    plan = plan_scene(parse_scene(ball), method="texture-space")
    assert not plan.on("translucent shadow maps")
    assert "thinnest part light cuts through" in next(d.why for d in plan.decisions if d.name == "translucent shadow maps")


def test_layered_profile_only_for_layered_materials():
    assert plan_scene(parse_scene(scene_dict(material={"preset": "skin"}))).on("layered profile")
    assert not plan_scene(parse_scene(scene_dict(material={"name": "skin1"}))).on("layered profile")


def test_looser_target_gives_fewer_gaussians_and_each_meets_its_target():
    # The dipole: the transport profile's 1/r core is not met by 12 Gaussians at 1 %
    # (tests/jsss/render/test_profile_choice.py measures what it places beyond a pixel).
    scene = parse_scene(scene_dict(material={"name": "ketchup", "profile": "dipole"}))
    tight = plan_scene(scene, accuracy=0.02, method="texture-space")
    loose = plan_scene(scene, accuracy=0.3, method="texture-space")
    assert len(loose.variances) < len(tight.variances)
    assert loose.max_ratio > tight.max_ratio
    for plan, target in ((tight, 0.02), (loose, 0.3)):
        error = reduction_error(scene.material, plan.variances, resolution=plan.pixel_size)
        assert np.max(error) <= target / 2 and np.isclose(np.max(error), plan.profile_error)


def test_specular_off_when_the_material_has_none():
    plan = plan_scene(parse_scene(scene_dict(material={"name": "marble", "specular": 0.0})))
    assert not plan.on("specular")
    assert "plan:" in plan.describe() and "specular" in plan.describe()


# --- choosing among the four methods from the calibration table -----------------------------

from jsss.render.calibration import (CalibrationRow, FrameFeatures, choose_method, estimate_methods,  # noqa: E402
                                     leave_one_scene_out, load_calibration, save_calibration)
from jsss.render.planner import frame_features  # noqa: E402


def _row(method, knob, reach, error, ms, prep=0.0, work=100, scene="s", backlit=0.0, curvature=0.2, closed=True):
    return CalibrationRow(scene, 72 * reach, method, knob, error, ms, work, prep, closed, blur_frame=reach,
                          backlit=backlit, curvature=curvature)


def _frame(reach, backlit=0.0, curvature=0.2, closed=True):
    return FrameFeatures(72 * reach, reach, closed, backlit, curvature)


SYNTHETIC = (_row("lambert", "", 0.01, 0.01, 1.0), _row("lambert", "", 0.1, 0.30, 1.0),
             _row("image-space", "32 spp", 0.01, 0.05, 20.0), _row("image-space", "32 spp", 0.1, 0.06, 20.0),
             _row("texture-space", "profile 5 %", 0.01, 0.02, 50.0, prep=30.0),
             _row("texture-space", "profile 5 %", 0.1, 0.02, 50.0, prep=30.0),
             _row("normal filtering", "spectral", 0.1, 0.3, 1.0, prep=50.0))


def test_estimates_take_the_worst_alike_frame_and_scale_time_by_work():
    work = {"lambert": 200, "image-space": 200, "normal filtering": 200, "texture-space": 100}
    estimates = {e.method: e for e in estimate_methods(SYNTHETIC, _frame(0.08), work)}
    assert estimates["lambert"].error == 0.30 and "alike" in estimates["lambert"].basis
    assert estimates["image-space"].ms == 40.0  # twice the pixels
    assert estimates["texture-space"].ms == 80.0  # frame + its own preparation
    assert estimates["normal filtering"].ms == 52.0  # frames follow the pixels, the eigenvectors do not
    near = {e.method: e for e in estimate_methods(SYNTHETIC, _frame(0.012), work)}
    assert near["lambert"].error == 0.01
    # Nothing alike (reach 20x beyond every frame): the worst frame of the kind, and it says so.
    far = {e.method: e for e in estimate_methods(SYNTHETIC, _frame(2.0), work)}
    assert far["lambert"].error == 0.30 and "no alike frame" in far["lambert"].basis


def test_light_from_behind_and_an_open_surface_are_not_matched_to_front_lit_spheres():
    """A back-lit frame at the same reach as a front-lit one is predicted from back-lit frames
    only (Lambert misses the light through the silhouette), an open one from open ones."""
    rows = SYNTHETIC + (_row("lambert", "", 0.1, 0.07, 1.0, scene="b", backlit=0.9),
                        _row("lambert", "", 0.1, 0.15, 1.0, scene="p", closed=False, curvature=0.0))
    work = dict.fromkeys(("lambert", "image-space", "normal filtering", "texture-space"), 100)
    lambert = lambda features: next(e for e in estimate_methods(rows, features, work) if e.method == "lambert")  # noqa: E731
    assert lambert(_frame(0.1, backlit=0.8)).error == 0.07 and "b" in lambert(_frame(0.1, backlit=0.8)).basis
    assert lambert(_frame(0.1, closed=False, curvature=0.0)).error == 0.15
    assert lambert(_frame(0.1)).error == 0.30
    assert "no alike frame" in lambert(_frame(0.1, curvature=0.9)).basis  # a much tighter curve
    try:
        estimate_methods(rows, 8.0, work)
    except TypeError as error:
        assert "FrameFeatures" in str(error)
    else:
        raise AssertionError("a bare blur was accepted")


def test_frame_features_do_not_depend_on_the_resolution_and_see_the_back_light():
    """The same framing at 96 x 72 and 320 x 240 has one reach in the frame (the pixels differ
    3.3x); skin_backlit's sun travels towards the camera, marble's lights do not."""
    from jsss.render import load_scene
    from jsss.render.comparison import scene_at_distance

    skin = load_scene(EXAMPLES / "skin_backlit.toml")
    small, large = (frame_features(scene_at_distance(skin, 1.0, width=w, height=h)) for w, h in ((96, 72), (320, 240)))
    assert large.blur_pixels == pytest.approx(small.blur_pixels * 240 / 72, rel=1e-6)
    assert large.blur_frame == pytest.approx(small.blur_frame, rel=1e-9)
    assert small.backlit > 0.9 and small.closed and 0.1 < small.curvature < 1
    marble = frame_features(load_scene(EXAMPLES / "marble_sphere.toml"))
    plane = frame_features(load_scene(EXAMPLES / "ketchup_plane.toml"))
    assert marble.backlit == 0.0 and (plane.closed, plane.curvature) == (False, 0.0)


def test_choice_is_the_cheapest_meeting_the_target_else_the_most_accurate():
    work = dict.fromkeys(("lambert", "image-space", "normal filtering", "texture-space"), 100)
    estimates = estimate_methods(SYNTHETIC, _frame(0.1), work)
    assert choose_method(estimates, 0.1)[0].method == "image-space"
    assert choose_method(estimates, 0.5)[0].method == "lambert"
    best, why = choose_method(estimates, 0.001)
    assert best.method == "texture-space" and "no method is predicted to meet" in why


def test_calibration_table_round_trips_and_bad_tables_are_named(tmp_path):
    path = save_calibration(SYNTHETIC, tmp_path / "table.json", measured="today")
    assert load_calibration(path) == SYNTHETIC
    (tmp_path / "bad.json").write_text("{}")
    for bad in (tmp_path / "bad.json", tmp_path / "missing.json"):
        try:
            load_calibration(bad)
        except ValueError as error:
            assert str(bad) in str(error) and "calibrate" in str(error)
        else:
            raise AssertionError("a bad table was accepted")


def _predicted_ms(plan):
    return next(e.ms for e in plan.estimates if (e.method, e.knob) == (plan.method, plan.knob))


def test_shipped_table_picks_a_cheaper_method_for_a_looser_target_and_says_why():
    scene = parse_scene(scene_dict(material={"name": "ketchup"}, geometry={"shape": "plane", "width": 60.0},
                                   camera={"position": [0.0, -70.0, 55.0], "fov": 40, "resolution": [64, 48]}))
    tight, loose = plan_scene(scene, accuracy=0.04), plan_scene(scene, accuracy=0.3)
    assert _predicted_ms(loose) < _predicted_ms(tight)
    for plan in (tight, loose):
        chosen = next(e for e in plan.estimates if (e.method, e.knob) == (plan.method, plan.knob))
        cheaper = [e for e in plan.estimates if e.ms < chosen.ms]
        target = 0.04 if plan is tight else 0.3
        assert chosen.error <= target or "no method" in plan.method_why
        assert all(e.error > target for e in cheaper)  # nothing cheaper would have met the target
        text = plan.describe()
        assert "predicted for this scene" in text and f"method: {plan.method}" in text


def test_shipped_table_follows_the_measured_errors_of_a_front_lit_sphere():
    """The marble sphere from its own camera: at the calibration's 96 x 72 Lambert measured
    2.4 % and is the cheapest, so it does for 5 %. At 320 x 240 (and for 2 % at both) the
    choice is the cheapest method predicted to meet the target: since 2026-12-04 a homogeneous
    medium's Lambert frame holds the oblique-incidence law (its H solve per frame, its lookup
    per pixel), and at 320 x 240 it measured 8-12 ms against texture space's 7 ms on its 64^2
    texels, so either may be predicted cheaper. From 20x as
    far the profile spans a fraction of a pixel, and the prediction rests on the far frames
    (checks the shipped table: rerunning the calibration may move these numbers, and this test
    says so)."""
    for resolution in ([96, 72], [320, 240]):
        near = parse_scene(scene_dict(camera={"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": resolution}))
        loose = plan_scene(near, accuracy=0.05)
        chosen = next(e for e in loose.estimates if (e.method, e.knob) == (loose.method, loose.knob))
        assert chosen.error <= 0.05 and all(e.error > 0.05 for e in loose.estimates if e.ms < chosen.ms)
        assert loose.method == "lambert" or resolution == [320, 240]
        tight = plan_scene(near, accuracy=0.02)
        chosen = next(e for e in tight.estimates if (e.method, e.knob) == (tight.method, tight.knob))
        assert tight.method != "lambert" and chosen.error <= 0.02
        assert all(e.error > 0.02 for e in tight.estimates if e.ms < chosen.ms)
    far = parse_scene(scene_dict(camera={"position": [0.0, -2200.0, 600.0], "fov": 28, "resolution": [96, 72]}))
    far_plan, near_plan = plan_scene(far, accuracy=0.05), plan_scene(near, accuracy=0.05)
    assert far_plan.blur_pixels < near_plan.blur_pixels / 10
    # There Lambert and texture space tie (2.6 and 2.5 % predicted, 3.1 and 3.0 ms in the fifth
    # rerun of 2026-12-05, Lambert cheaper in the fourth): the cheapest predicted to meet 5 %.
    chosen = next(e for e in far_plan.estimates if (e.method, e.knob) == (far_plan.method, far_plan.knob))
    assert chosen.error <= 0.05 and all(e.error > 0.05 for e in far_plan.estimates if e.ms < chosen.ms)
    assert "marble_sphere" in chosen.basis and far_plan.method in ("lambert", "texture-space")
    assert f"{far_plan.blur_pixels:.3g} pixels" in far_plan.describe() and "front-lit" in far_plan.describe()


def test_method_override_and_bad_method_names():
    scene = parse_scene(scene_dict())
    plan = plan_scene(scene, method="image-space", samples=16)
    assert plan.method == "image-space" and plan.samples == 16 and plan.knob == "16 spp"
    assert plan.on("image-space integration") and not plan.on("diffusion") and not plan.on("texture geometry")
    assert plan.method_why.startswith("set by")
    for kwargs, word in (({"method": "raytrace"}, "method"), ({"samples": 0}, "samples"),
                         ({"normal_filter": "fancy"}, "normal_filter"), ({"accuracy": 1.5}, "accuracy")):
        try:
            plan_scene(scene, **kwargs)
        except ValueError as error:
            assert word in str(error)
        else:
            raise AssertionError(f"{kwargs} accepted")


def test_the_planner_never_picks_a_method_whose_measured_error_on_an_alike_frame_exceeds_the_target():
    """On the shipped table: for every calibration frame and target, the method chosen from all
    rows, where it is predicted to meet the target, met it on that frame (each frame is alike
    to itself, and a prediction is the worst alike frame)."""
    rows = load_calibration()
    frames: dict = {}
    for r in rows:
        frames.setdefault((r.scene, r.blur_pixels), []).append(r)
    checked = 0
    for frame in frames.values():
        measured = {(r.method, r.knob): r.error for r in frame}
        work = {r.method: r.work for r in frame}
        for target in (0.2, 0.05, 0.02):
            chosen, _ = choose_method(estimate_methods(rows, frame[0].features, work), target)
            if chosen.error <= target:
                assert measured[(chosen.method, chosen.knob)] <= target, (frame[0].scene, target, chosen)
                checked += 1
    assert checked >= 20


def test_leave_one_scene_out_predicts_each_scene_from_the_others_only():
    """The held-out scene's rows never enter its predictions: a scene unlike the rest gets the
    pessimistic fallback, and every frame of every scene is reported with its measured error."""
    rows = SYNTHETIC + (_row("lambert", "", 0.1, 0.07, 1.0, scene="b", backlit=0.9),
                        _row("texture-space", "profile 5 %", 0.1, 0.01, 50.0, scene="b", backlit=0.9))
    out = leave_one_scene_out(rows, 0.05)
    assert {f["scene"] for f in out} == {"s", "b"} and len(out) == 3
    (held,) = [f for f in out if f["scene"] == "b"]
    # Predicted from "s" alone (front-lit): no alike frame, the worst of all its frames.
    assert held["errors"][("lambert", "")] == (0.30, 0.07) and held["chosen"] == ("texture-space", "profile 5 %")
    assert held["meets"] and held["measured"] == 0.01


def test_examples_do_what_their_comments_say():
    """skin_backlit: the planner picks texture space (the back light wraps around the
    silhouette, which Lambert measured 6.0 % off on that framing) with the layered profile;
    ketchup_plane: flat UVs, so no stretch correction; the textured examples turn the maps on."""
    from jsss.render import load_scene

    skin = plan_scene(load_scene(EXAMPLES / "skin_backlit.toml"))
    assert skin.method == "texture-space" and skin.on("layered profile") and skin.on("diffusion")
    assert "skin_backlit" in next(e.basis for e in skin.estimates if e.method == "lambert")
    ketchup = plan_scene(load_scene(EXAMPLES / "ketchup_plane.toml"), method="texture-space")
    assert not ketchup.on("stretch correction")
    # marble_veins: a colour map Lambert cannot blur; checker_plane: parameter maps, two media on
    # the corners of a 2 x 2 basis (exact blend).
    veins = plan_scene(load_scene(EXAMPLES / "marble_veins.toml"))
    assert veins.on("surface maps") and veins.method in ("texture-space", "image-space")
    assert any("unspread maps" in e.basis for e in veins.estimates)
    checker = plan_scene(load_scene(EXAMPLES / "checker_plane.toml"))
    assert checker.on("surface maps") and checker.basis.size == 4 and checker.basis.error < 1e-9


def test_a_layered_profile_is_kept_by_its_numbers_and_a_changed_stack_is_computed_anew():
    """Planning asks for the stack's profile three times; it is kept, keyed by the stack's
    numbers. A thicker top layer (same object structure) must not be served the kept one:
    both equal a fresh Kubelka-Munk stack."""
    import dataclasses

    from jsss.gaussians import layers_as_gaussians, to_gaussian_sum
    from jsss.render.profiles import full_profile

    material = parse_scene(scene_dict(material={"preset": "skin"})).material
    top = material.layers[0]
    thicker = dataclasses.replace(material, layers=(dataclasses.replace(top, thickness=2 * top.thickness),
                                                    *material.layers[1:]))
    for m in (material, thicker, material):
        expected = to_gaussian_sum(layers_as_gaussians(list(m.layers), m.base)[0])
        got = full_profile(m)
        np.testing.assert_array_equal(got.weights, expected.weights)
        np.testing.assert_array_equal(got.variances, expected.variances)
    assert full_profile(material) is full_profile(material)
    assert not np.array_equal(full_profile(thicker).weights, full_profile(material).weights)


def test_the_planners_unspread_map_error_is_a_pessimistic_bound_on_the_veined_marble():
    """Lambert applies the colour map at one point; texture space spreads it with the light. The
    planner's estimate of what that costs (the map blurred in UV by the profile's RMS radius) must
    not be below the frame's measured difference, nor far above it (measured 2026-12-03: 6.0 %
    estimated, 3.3 % in the frame; the estimate counts the whole map, the frame what it sees)."""
    import dataclasses

    import jax.numpy as jnp

    from jsss.render import load_scene, render
    from jsss.render.planner import map_spread_error

    scene = load_scene(EXAMPLES / "marble_veins.toml")
    plain = dataclasses.replace(scene, material=dataclasses.replace(scene.material, maps=None))
    frames = []
    for method in ("lambert", "texture-space"):
        plan = plan_scene(scene, method=method)
        frames.append((render(scene, plan, dtype=jnp.float64).radiance, render(plain, plan, dtype=jnp.float64).radiance))
    lit = np.all([reference.max(-1) > 0.02 * reference.max() for _, reference in frames], axis=0)
    factors = [mapped[lit] / reference[lit] for mapped, reference in frames]
    measured = np.sqrt(np.mean((factors[0] - factors[1]) ** 2) / np.mean(factors[1] ** 2))
    plan = plan_scene(scene)
    estimate = map_spread_error(scene, plan.blur_pixels * plan.pixel_size)
    assert measured > 0.01  # the veins are visible at the profile's scale
    assert measured <= estimate <= 3 * measured


def test_a_scene_in_metres_is_told_that_lengths_are_millimetres(recwarn):
    """A marble ball written in metres (radius 0.02) planned a profile 27000 pixels wide and
    rendered a flat wash without a word; one in millimetres plans in silence."""
    import warnings

    from jsss.render.planner import ScaleWarning

    def scene(radius, distance):
        return parse_scene({"geometry": {"shape": "sphere", "radius": radius}, "material": {"name": "marble"},
                            "lights": [{"type": "directional", "direction": [0.6, 0.8, -0.5]}],
                            "camera": {"position": [0.0, -distance, 0.0], "resolution": [32, 24]}})

    with pytest.warns(ScaleWarning, match=r"0.04 mm wide: lengths in a scene are millimetres"):
        plan_scene(scene(0.02, 0.11), method="lambert")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        plan_scene(scene(20.0, 110.0), method="lambert")


def test_a_kept_layered_profile_is_read_back_from_disk_and_a_damaged_file_is_recomputed(tmp_path, monkeypatch):
    """keep_profiles_in (what the console scripts call): a new process reads the stack's profile
    and its reference from the folder, equal to the computed ones; a damaged file warns and is
    replaced; without a folder nothing is written."""
    from jsss.render import profiles
    from jsss.render.profiles import full_profile, keep_profiles_in

    material = parse_scene(scene_dict(material={"preset": "skin"})).material
    monkeypatch.setattr(profiles, "_layered_profiles", type(profiles._layered_profiles)())
    keep_profiles_in(tmp_path)
    try:
        computed = full_profile(material)
        files = sorted((tmp_path / "profiles").glob("sum-*.npz"))
        assert len(files) == 1
        profiles._layered_profiles.clear()  # a new process: memory empty, the folder kept
        read = full_profile(material)
        np.testing.assert_array_equal(read.weights, computed.weights)
        np.testing.assert_array_equal(read.variances, computed.variances)
        files[0].write_bytes(b"not an npz")
        profiles._layered_profiles.clear()
        with pytest.warns(UserWarning, match="unreadable kept profile"):
            again = full_profile(material)
        np.testing.assert_array_equal(again.weights, computed.weights)
        assert np.load(files[0])["a0"].shape == np.shape(computed.weights)  # replaced
    finally:
        keep_profiles_in(None)
    profiles._layered_profiles.clear()
    before = sorted(tmp_path.rglob("*"))
    full_profile(material)
    assert sorted(tmp_path.rglob("*")) == before
