"""Closures (engine/shaders.py; no bpy): the description export fills, and the seed's
reduction of it that today's renderer draws, with a note for every approximation.

The reduction's expected values are the module docstring's table written out by hand for
each closure kind; the notes must name the node."""
import math

import numpy as np
import pytest

from lanterna.engine.shaders import CLOSURE_KINDS, Closure, lobe_names, seed_reduction


def test_defaults_fill_every_parameter_and_unknown_ones_are_refused():
    c = Closure("principled")
    assert set(c.params) == set(CLOSURE_KINDS["principled"])
    np.testing.assert_allclose(c.params["base_color"], 0.8)
    assert c.params["roughness"] == 0.5 and c.params["ior"] == 1.5
    with pytest.raises(ValueError, match="no parameter"):
        Closure("diffuse", params={"colour": (1, 1, 1)})
    with pytest.raises(ValueError, match="unknown closure kind"):
        Closure("velvet")


def test_translucent_closure_transmits_its_colour():
    seed = seed_reduction([Closure("translucent", params={"color": (0.1, 0.2, 0.3)},
                                   weight=(0.5, 0.5, 0.5))])
    np.testing.assert_allclose(seed.translucent, [0.05, 0.1, 0.15], rtol=1e-12)
    np.testing.assert_allclose(seed.diffuse, 0.0)


@pytest.mark.parametrize("closure, diffuse, specular, exitance, noted", [
    (Closure("principled", params={"base_color": (0.5, 0.4, 0.3), "metallic": 0.25,
                                   "roughness": 0.0, "emission": (1.0, 0.5, 0.25)}),
     [0.375, 0.3, 0.225], [0.125, 0.1, 0.075], [math.pi, math.pi / 2, math.pi / 4],
     []),
    (Closure("principled", params={"metallic": 1.0, "roughness": 0.3}, node="Copper"),
     [0, 0, 0], [0.8, 0.8, 0.8], [0, 0, 0], []),
    (Closure("principled", params={"transmission": 0.5}, node="P"),
     [0.4, 0.4, 0.4], [0.5 * math.sqrt(0.8)] * 3, [0, 0, 0],
     []),
    (Closure("principled", params={"specular_ior_level": 0.0}), [0.8] * 3, [0] * 3, [0] * 3,
     []),
    (Closure("diffuse", params={"roughness": 0.5}, node="D"), [0.8] * 3, [0] * 3, [0] * 3,
     ["Roughness 0.5 of Diffuse BSDF 'D'"]),
    (Closure("diffuse", params={"color": (0.2, 0.6, 0.9)}), [0.2, 0.6, 0.9], [0] * 3, [0] * 3,
     []),
    (Closure("glossy", params={"color": (0.9, 0.8, 0.7), "roughness": 0.05}), [0] * 3,
     [0.9, 0.8, 0.7], [0] * 3, []),
    (Closure("glossy", params={"roughness": 0.4}, node="G"), [0] * 3, [0.8] * 3, [0] * 3,
     []),
    (Closure("metallic", params={"physical": 1.0, "ior": (2.0, 1.0, 1.5),
                                 "extinction": (0.0, 1.0, 2.0)}, node="M"),
     [0] * 3, [1 / 9, 0.2, 4.25 / 10.25], [0] * 3, []),
    (Closure("glass", params={"ior": 1.5, "color": (1.0, 0.5, 0.25)}, node="Glass"), [0] * 3,
     [1.0, 0.5, 0.25], [0] * 3, []),
    (Closure("transparent", node="T"), [0] * 3, [1] * 3, [0] * 3,
     ["Transparent BSDF 'T': light reaches what lies behind it"]),
    (Closure("holdout", node="H"), [0] * 3, [0] * 3, [0] * 3,
     ["Holdout 'H' is not supported"]),
    # Translucent: no reflection; its rho_t is ``SeedMaterial.translucent`` (tested below).
    (Closure("translucent", params={"color": (0.1, 0.2, 0.3)}, node="L"), [0] * 3,
     [0] * 3, [0] * 3, []),
    (Closure("emission", params={"radiance": (2.0, 1.0, 0.0)}), [0] * 3, [0] * 3,
     [2 * math.pi, math.pi, 0], []),
])
def test_seed_reduction_follows_the_table(closure, diffuse, specular, exitance, noted):
    seed = seed_reduction([closure])
    np.testing.assert_allclose(seed.diffuse, diffuse, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(seed.specular, specular, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(seed.exitance, exitance, rtol=1e-12, atol=1e-15)
    assert len(seed.notes) == len(noted)
    for text, note in zip(noted, seed.notes):
        assert text in note


def test_weights_scale_and_sum():
    a = Closure("diffuse", params={"color": (1.0, 0.0, 0.0)}).scaled(0.75)
    b = Closure("glossy", params={"color": (0.0, 0.0, 0.8), "roughness": 0.0}).scaled(
        [0.25, 0.5, 0.25])
    seed = seed_reduction([a, b])
    np.testing.assert_allclose(seed.diffuse, [0.75, 0, 0])
    np.testing.assert_allclose(seed.specular, [0, 0, 0.2])
    assert seed_reduction([]).notes == []


def test_lobe_names_say_what_a_material_has():
    assert lobe_names([Closure("principled")]) == ["diffuse", "specular (dielectric)"]
    metal = Closure("principled", params={"metallic": 1.0, "coat_weight": 1.0})
    assert lobe_names([metal]) == ["specular (metal, F82 tint)", "coat"]
    glass = Closure("principled", params={"transmission": 1.0, "emission": (1.0, 0, 0)})
    assert lobe_names([glass]) == ["specular (dielectric)", "transmission", "emission"]
    assert lobe_names([Closure("diffuse").scaled(0.0), Closure("glass")]) == ["transmission"]


def test_approximations_of_the_principled_bsdf_are_named():
    """Subsurface (a diffuse of the Base Color) and Diffuse Roughness (Lambertian) are
    approximated: each gets a note naming the node; at their defaults, none. Thin Film is
    rendered everywhere Cycles has it, the glass too (no note)."""
    said = seed_reduction([Closure("principled", node="P", params={
        "subsurface_weight": 0.5, "diffuse_roughness": 0.3,
        "thin_film_thickness": 300.0})]).notes
    assert any("Subsurface Weight 0.5 of 'P'" in n for n in said)
    assert any("Diffuse Roughness 0.3 of 'P'" in n for n in said)
    assert not any("Thin Film" in n for n in said)
    said = seed_reduction([Closure("principled", node="P", params={
        "transmission": 1.0, "thin_film_thickness": 300.0})]).notes
    assert not any("Thin Film" in n for n in said)
    assert not seed_reduction([Closure("principled", node="P")]).notes
    for kind in ("metallic", "glass"):
        assert not seed_reduction([Closure(kind, node="F",
                                           params={"thin_film_thickness": 250.0})]).notes
