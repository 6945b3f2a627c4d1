"""One source of settings (issue 20): ``engine/settings.py`` against Blender's properties and the
command line.

* Every exposed field of ``RenderSettings`` is a ``Scene.lanterna`` property with the same
  default, hard minimum and maximum, label and description (enum items: the choices); the
  fields that are not exposed are absent. (Before, ``light_samples`` had minimum 1 in the UI
  and 0 in ``RenderSettings.validate``, and the bounce default had three copies.)
* ``RenderSettings.validate`` refuses exactly the values outside those limits, naming the
  setting and what it allows.
* The command line's flags take the same limits: a value the settings refuse, the CLI refuses
  with the setting's range in the message.
"""
import dataclasses
import importlib.util

import pytest

from lanterna.engine.scene import SceneError
from lanterna.engine.settings import SETTINGS, RenderSettings

DEFAULTS = dataclasses.asdict(RenderSettings())
NUMERIC = [n for n, s in SETTINGS.items() if s.minimum is not None]


@pytest.mark.parametrize("name", NUMERIC)
def test_validate_refuses_exactly_what_lies_outside_the_limits(name):
    spec = SETTINGS[name]
    integer = isinstance(DEFAULTS[name], int)
    step = 1 if integer else 1e-9 * max(1.0, abs(spec.maximum))
    for ok in (spec.minimum, spec.maximum):
        RenderSettings(**{name: int(ok) if integer else ok}).validate()
    for bad in (spec.minimum - step, spec.maximum + step):
        with pytest.raises(SceneError, match=f"Render settings: {name} = .* is out of range"):
            RenderSettings(**{name: int(bad) if integer else bad}).validate()
    if not integer:
        for bad in (float("nan"), float("inf")):
            with pytest.raises(SceneError, match=name):
                RenderSettings(**{name: bad}).validate()


def test_choices_are_checked():
    for name, spec in SETTINGS.items():
        if spec.choices:
            with pytest.raises(SceneError, match=f"{name} = 'nonsense' .*one of"):
                RenderSettings(**{name: "nonsense"}).validate()


def test_the_command_line_takes_the_same_limits(capsys):
    from lanterna.engine.blender import cli

    parser = cli.build_parser()
    for name in ("samples", "light_samples", "bounces", "photon_k", "cache_error",
                 "gather_guided", "threads"):
        spec = SETTINGS[name]
        flag = "--" + name.replace("_", "-")
        integer = isinstance(DEFAULTS[name], int)
        bad = spec.maximum + (1 if integer else 0.5)
        with pytest.raises(cli.UsageError, match=flag):
            parser.parse_args(["render", flag, str(int(bad) if integer else bad)])
        args = parser.parse_args(["render", flag, str(int(spec.maximum) if integer
                                                       else spec.maximum)])
        assert getattr(args, name) == spec.maximum


@pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason="needs the bpy module")
def test_blender_properties_are_the_settings_contract():
    import bpy

    from lanterna.engine.blender import registration

    was = registration.is_registered()
    registration.register()
    try:
        rna = bpy.types.Scene.bl_rna.properties["lanterna"].fixed_type.bl_rna.properties
        exposed = {n for n, s in SETTINGS.items() if s.exposed}
        own = {p.identifier for p in rna} - {"rna_type", "name", "use_irradiance_cache"}
        assert own == exposed
        problems = []
        for name in sorted(exposed):
            spec, prop, default = SETTINGS[name], rna[name], DEFAULTS[name]
            if prop.name != spec.label or prop.description != spec.description:
                problems.append(f"{name}: label or description differs")
            if spec.choices:
                items = [(i.identifier, i.name) for i in prop.enum_items]
                wanted = [(c.upper().replace("-", "_"), label) for c, label, _ in spec.choices]
                if items != wanted or prop.default != default.upper().replace("-", "_"):
                    problems.append(f"{name}: items {items} default {prop.default}")
                continue
            if prop.type == 'BOOLEAN':
                if prop.default != default:
                    problems.append(f"{name}: default {prop.default} != {default}")
                continue
            if (prop.default != pytest.approx(default) or prop.hard_min != pytest.approx(spec.minimum)
                    or prop.hard_max != pytest.approx(spec.maximum)):
                problems.append(f"{name}: default/min/max {prop.default}, {prop.hard_min}, "
                                f"{prop.hard_max} against {default}, {spec.minimum}, "
                                f"{spec.maximum}")
        assert problems == []
    finally:
        if not was:
            registration.unregister()
