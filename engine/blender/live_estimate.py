"""The cost estimate the render panel shows (``ui/panels.py``, ``LANTERNA_RENDER_PT_estimate``):
``engine/estimate.py`` on the scene's facts, with the calibrated rates of ``engine/data``.

What it computes
    ``panel_estimate(context)`` -> (``estimate.Estimate`` or None, a note); never raises (a
    panel must draw whatever happens). The scene's facts (``estimate.scene_facts``) need an
    export, too slow to repeat on every redraw of a big scene, so they are cached under a cheap
    signature of the depsgraph (per evaluated object: name, type, polygon and vertex counts,
    materials; per light: type, power, size, flags; the world; the camera and its lens); the
    estimate itself is recomputed from the cached facts on every redraw (arithmetic), so
    changes of the settings and the resolution show at once. A scene whose signature changed
    is exported again when it has at most ``LIVE_EXPORT_TRIANGLES`` polygons; a bigger one
    keeps its older facts, marked as such, or takes the facts of the last F12 render (its
    report's estimate), or, with neither, says how to get an estimate (``lanterna render
    SCENE.blend --dry-run``).
"""
from __future__ import annotations

from .. import estimate as est
from . import session
from .export import export_scene, export_settings, render_border, render_resolution

LIVE_EXPORT_TRIANGLES = 200_000

_PANEL_CACHE: dict = {}


def _signature(depsgraph, bscene) -> tuple:
    """A cheap key of what the facts depend on (module docstring)."""
    items = []
    polygons = 0
    for obj in depsgraph.objects:
        row = [obj.name, obj.type]
        data = getattr(obj, "data", None)
        if obj.type == 'MESH' and data is not None:
            polygons += len(data.polygons)
            row += [len(data.polygons), len(data.vertices),
                    tuple(m.name if m else "" for m in data.materials)]
        elif obj.type == 'LIGHT' and data is not None:
            row += [data.type, round(float(data.energy), 6), tuple(data.color),
                    round(float(getattr(data, "size", 0.0)), 6),
                    round(float(getattr(data, "size_y", 0.0)), 6),
                    round(float(getattr(data, "angle", 0.0)), 6),
                    round(float(getattr(data, "spread", 0.0)), 6),
                    bool(getattr(getattr(data, "lanterna", None), "shadow_photons", True))]
        items.append(tuple(row))
    world = bscene.world
    wkey = world.name_full if world is not None else ""
    camera = bscene.camera
    cam = ((camera.name, round(float(getattr(camera.data, "lens", 0.0)), 6),
            round(float(getattr(camera.data, "sensor_width", 0.0)), 6))
           if camera is not None else "")
    return tuple(sorted(items)), polygons, wkey, cam, bscene.name


def _last_render_facts():
    """The facts of the last F12 render (its report's estimate), or None."""
    facts = (((session.LAST_RENDER or {}).get("report") or {}).get("estimate") or {}).get("facts")
    try:
        return est.SceneFacts.from_dict(facts) if facts else None
    except (KeyError, TypeError, ValueError):
        return None


def panel_estimate(context):
    """(estimate or None, note) for the render panel; never raises."""
    try:
        import bpy

        bscene = context.scene
        depsgraph = bpy.context.evaluated_depsgraph_get()
        key = _signature(depsgraph, bscene)
        cached = _PANEL_CACHE.get(bscene.name)
        note = ""
        if cached is None or cached[0] != key:
            if key[1] <= LIVE_EXPORT_TRIANGLES:
                scene = export_scene(depsgraph)
                facts = est.scene_facts(scene)
                _PANEL_CACHE[bscene.name] = (key, facts)
            elif cached is not None:
                facts = cached[1]
                note = (f"The scene changed since its facts were taken (over "
                        f"{LIVE_EXPORT_TRIANGLES:,} polygons: not exported while drawing)")
            else:
                facts = _last_render_facts()
                if facts is None:
                    return None, (f"The scene has over {LIVE_EXPORT_TRIANGLES:,} polygons: "
                                  "render once, or 'lanterna render SCENE.blend --dry-run'")
                note = "Scene facts from the last render"
        else:
            facts = cached[1]
        resolution = render_resolution(bscene.render)
        border = render_border(bscene.render, resolution) or (0, 0, *resolution)
        facts = est.SceneFacts(**{**facts.__dict__, "frame": tuple(resolution),
                                  "border": tuple(border),
                                  "window": (border[2] - border[0], border[3] - border[1])})
        settings = export_settings(bscene)
        return est.estimate_from_facts(facts, settings, available=est.available_memory()), note
    except Exception as exc:   # a panel must draw whatever happens
        return None, f"No estimate: {type(exc).__name__}: {exc}"
