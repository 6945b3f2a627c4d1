"""The 3D viewport side of Lanterna: overlay settings and the sidebar tab "Lanterna".

``Scene.lanterna_overlay`` (``LanternaOverlaySettings``): what the viewport overlay
(``engine/blender/overlay_draw.py``) draws of the maps the last render, bake or load of the
scene kept (``engine/blender/session.py``):

===================  ==========  ==============================================================
property             default     meaning
===================  ==========  ==============================================================
show                 on          draw the maps at all (the tab's header checkbox)
show_photons         on          the photon map (thesis Fig. 12.5)
show_shadow_photons  off         the shadow photons
show_cache           off         the irradiance-cache records (thesis Fig. 12.4)
photons_color        Power       Power (luminance, viridis), RGB (the photon's colour),
                                 Bounces (one colour per bounce count)
shadow_color         Crossings   Crossings (direct yellow, shadow blue), Class (the
                                 representatives: lit yellow, umbra blue, penumbra magenta),
                                 Light (one colour per light)
cache_color          Radius      Radius (log R, viridis), Irradiance, Usage
point_size           3 px        size of a drawn point [pixels], 1-20
max_points           100 000     points drawn per kind, the most important first (the density)
opacity              1           alpha of the points, 0-1
in_front             on          draw over the surfaces the points lie on (off: depth tested)
===================  ==========  ==============================================================

``LANTERNA_VIEW3D_PT_maps`` (View3D > Sidebar > Lanterna): the switch, one row per kind with
its colouring and the counts drawn / total, the display settings, and the buttons Bake,
Clear, Save, Load and Export Report (``ops/bake.py``). The tab shows while Lanterna is the
render engine or the scene has maps. ``register()`` also adds the overlay's draw handler
(nothing in background mode); ``unregister()`` removes everything.
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from ..engine import overlay
from ..engine.blender import overlay_draw, session

ENGINE_ID = "LANTERNA"

_DESCRIPTIONS = {
    "power": ("Power", "Luminance of the photon's power over the map's 99th percentile, "
                       "viridis colour map (dark purple: dim, yellow: bright)"),
    "rgb": ("RGB", "The photon's own colour: its RGB power over its largest channel"),
    "bounces": ("Bounces", "One colour per number of bounces before the photon was stored"),
    "crossings": ("Crossings", "Direct photons (first hit) yellow, shadow photons (behind a "
                               "surface) blue"),
    "class": ("Class", "Only the representatives, by their class: lit yellow, umbra blue, "
                       "penumbra magenta"),
    "light": ("Light", "One colour per light the photon left"),
    "radius": ("Radius", "Record radius R on a log scale, viridis (small: purple, large: yellow)"),
    "irradiance": ("Irradiance", "Luminance of the record's irradiance over the 99th "
                                 "percentile, viridis"),
    "usage": ("Usage", "Points each record served in the last render, log scale, viridis"),
}


def _items(kind):
    return tuple((name.upper(), *_DESCRIPTIONS[name]) for name in overlay.COLOR_BY[kind])


def _redraw(_self, _context):
    session.redraw_viewports()


class LanternaOverlaySettings(bpy.types.PropertyGroup):
    """What the viewport overlay draws of the kept maps."""

    show: BoolProperty(name="Show Maps", default=True, update=_redraw,
                       description="Draw the kept photon map, shadow photons and cache records "
                                   "in the 3D viewport")
    show_photons: BoolProperty(name="Photons", default=True, update=_redraw,
                               description="Draw the photon map's photons")
    show_shadow_photons: BoolProperty(name="Shadow Photons", default=False, update=_redraw,
                                      description="Draw the shadow photons")
    show_cache: BoolProperty(name="Cache Records", default=False, update=_redraw,
                             description="Draw the irradiance cache's records")
    photons_color: EnumProperty(name="Colour", items=_items("photons"), default='POWER',
                                update=_redraw, description="How photons are coloured")
    shadow_color: EnumProperty(name="Colour", items=_items("shadow_photons"),
                               default='CROSSINGS', update=_redraw,
                               description="How shadow photons are coloured")
    cache_color: EnumProperty(name="Colour", items=_items("cache"), default='RADIUS',
                              update=_redraw, description="How cache records are coloured")
    point_size: FloatProperty(name="Point Size", default=3.0, min=1.0, max=20.0,
                              subtype='PIXEL', update=_redraw,
                              description="Size of a drawn point, in pixels")
    max_points: IntProperty(name="Max Points", default=overlay.DEFAULT_MAX_POINTS, min=1,
                            max=50_000_000, soft_max=5_000_000, subtype='NONE', update=_redraw,
                            description="Points drawn of each kind (the density): the most "
                                        "important first (a power-weighted random order for "
                                        "photons, uniform for the others)")
    opacity: FloatProperty(name="Opacity", default=1.0, min=0.0, max=1.0, subtype='FACTOR',
                           update=_redraw, description="Opacity of the points")
    in_front: BoolProperty(name="In Front", default=True, update=_redraw,
                           description="Draw the points over the surfaces they lie on (off: "
                                       "points behind geometry are hidden)")


class LANTERNA_VIEW3D_PT_maps(bpy.types.Panel):
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Lanterna"
    bl_label = "Lanterna Maps"

    @classmethod
    def poll(cls, context):
        scene = context.scene
        return scene is not None and (scene.render.engine == ENGINE_ID
                                      or session.get(scene.name) is not None)

    def draw_header(self, context):
        self.layout.prop(context.scene.lanterna_overlay, "show", text="")

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        settings = scene.lanterna_overlay

        row = layout.row(align=True)
        row.operator("lanterna.bake", icon='LIGHT')
        row.operator("lanterna.clear", icon='X', text="Clear")
        row = layout.row(align=True)
        row.operator("lanterna.save_maps", icon='FILE_TICK', text="Save")
        row.operator("lanterna.load_maps", icon='FILE_FOLDER', text="Load")
        layout.operator("lanterna.export_report", icon='TEXT')

        kept = session.info(scene.name)
        if not kept:
            layout.label(text="No maps: render or bake", icon='INFO')
        else:
            text = {"render": "From the last render", "bake": "Baked",
                    "load": "Loaded"}.get(kept["source"], kept["source"])
            layout.label(text=text, icon='CHECKMARK')
            if kept["path"]:
                layout.label(text=bpy.path.basename(kept["path"]), icon='FILE')

        counts = overlay_draw.counts(scene.name, settings)
        col = layout.column()
        col.active = settings.show
        for kind, switch, color in overlay_draw.KIND_PROPS:
            box = col.box()
            row = box.row()
            row.prop(settings, switch)
            drawn, total = counts[kind]
            row.label(text=f"{drawn:,} / {total:,}")
            sub = box.row()
            sub.active = getattr(settings, switch)
            sub.prop(settings, color, text="")
        col.prop(settings, "point_size")
        col.prop(settings, "max_points")
        col.prop(settings, "opacity", slider=True)
        col.prop(settings, "in_front")


classes = (LanternaOverlaySettings, LANTERNA_VIEW3D_PT_maps)


def register():
    from ..engine.blender.classes import register_classes
    register_classes(classes)
    bpy.types.Scene.lanterna_overlay = PointerProperty(type=LanternaOverlaySettings)
    overlay_draw.register()


def unregister():
    from ..engine.blender.classes import unregister_classes
    overlay_draw.unregister()
    if hasattr(bpy.types.Scene, "lanterna_overlay"):
        del bpy.types.Scene.lanterna_overlay
    unregister_classes(classes)
