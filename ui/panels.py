"""Properties-editor panels for the Lanterna engine, laid out as Cycles lays out its own.

Every Lanterna panel shares :class:`LanternaPanel`: ``COMPAT_ENGINES = {'LANTERNA'}`` and a
poll on ``context.engine``, so they show only while Lanterna is the scene's render engine.
Sub-panels hang under their parent with ``bl_parent_id``; properties are drawn with
``use_property_split``; a panel that switches a feature on carries the switch in its header
(``draw_header``). Settings that the chosen quality preset sets (``settings.PRESETS``) are
greyed out; so are settings the current mode or method does not use.

Render (``scene.lanterna``)
    ``LANTERNA_RENDER_PT_sampling``            preset, mode, samples, light samples, bounces
      ``LANTERNA_RENDER_PT_sampling_advanced``   seed, threads
      ``LANTERNA_RENDER_PT_estimate``            estimated time and memory per stage
    ``LANTERNA_RENDER_PT_photons``             photon count, k per estimate, max radius,
                                                filter, look-ups per pixel (seed 9.2-9.5)
    ``LANTERNA_RENDER_PT_indirect``            how full mode computes indirect light
      ``LANTERNA_RENDER_PT_final_gather``        gather M x N, guided rays (seed 8, Eq. 8.4-8.6)
      ``LANTERNA_RENDER_PT_irradiance_cache``    switch in the header (Indirect = Irradiance
                                                  Cache); error a, gradients (seed 10)
    ``LANTERNA_RENDER_PT_shadow_photons``      switch in the header (``shadow_photons``); the
                                                area lights with their own switch (seed 7.2,
                                                9.6)
    ``LANTERNA_RENDER_PT_last_render``         status of the last F12 render
      ``LANTERNA_RENDER_PT_last_render_plan``    every stage of the plan, run or skipped, and why
      ``LANTERNA_RENDER_PT_last_render_timings`` export and per-stage seconds, share of total
      ``LANTERNA_RENDER_PT_last_render_warnings`` the render's warnings
    The Last Render panels read ``engine.blender.session.LAST_RENDER``, which the
    RenderEngine fills at the end of every render (the pipeline's report, warnings, error,
    export and total seconds).
Material (``material.lanterna``)
    ``LANTERNA_MATERIAL_PT_surface``     the node tree's Surface input, edited as in Cycles
    ``LANTERNA_MATERIAL_PT_radiometry``  the seed's rho_d, rho_s and M (section 3.2). Given by
        hand: editable, with a live check that rho_d + rho_s <= 1 in every channel (an alert
        row names each channel over 1 and its sum: such a material creates energy, and the
        render scales it down). Derived from the nodes: the values the render will use, read
        only, from ``export.material_from_nodes`` (the exporter's own derivation), with what
        the derivation had to approximate.
Light (``light.lanterna``)
    ``LANTERNA_LIGHT_PT_light``    type, colour, power, size or radius, spot cone
      ``LANTERNA_LIGHT_PT_photons``  photon share; shadow photons on/off (area lights only:
                                     points, spots and suns need one shadow ray each)
Camera
    ``LANTERNA_CAMERA_PT_panorama``  under Blender's Lens panel, for a panoramic camera: its
                                     projection and, for equirectangular, the latitude and
                                     longitude ranges (Blender draws them for Cycles only)
World
    ``LANTERNA_WORLD_PT_surface``  the world's Surface input (a constant colour is a uniform
                                   environment light)

Blender's own engine-independent panels (output format, frame range, output path, colour
management, camera and lens, material slots, object visibility, ...) are opened to the engine
the way add-on engines do: ``'LANTERNA'`` is added to the ``COMPAT_ENGINES`` set of every
built-in panel that lists ``'BLENDER_RENDER'``, plus ``_EXTRA_BUILTINS``, except
``_EXCLUDED_BUILTINS`` (Blender's light panel and its spot sub-panel, which
``LANTERNA_LIGHT_PT_light`` replaces, and the previews Lanterna does not render), with the
Depth of Field panels (Lanterna renders the thin lens as Cycles does). ``unregister`` removes
``'LANTERNA'``
from every set again, including sets an earlier registration left behind.
"""
from __future__ import annotations

import math
import textwrap

import bpy

from ..engine.blender import session
from ..engine.shaders import lobe_names

ENGINE_ID = "LANTERNA"
MAX_LISTED_LIGHTS = 12      # area lights listed in the Shadow Photons panel
MAX_WARNINGS = 30           # warnings listed in the Last Render > Warnings panel


class LanternaPanel:
    """Mixin of every Lanterna panel."""

    COMPAT_ENGINES = {ENGINE_ID}
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class LanternaRenderPanel(LanternaPanel):
    bl_context = "render"


def _split(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout


def _wrap(layout, text: str, context=None, icon: str = 'NONE', alert: bool = False):
    """``text`` as labels wrapped to the region's width (60 characters without a region)."""
    region = getattr(context, "region", None) if context is not None else None
    width = getattr(region, "width", 0) or 0
    chars = max(24, int(width / 7)) if width > 40 else 60
    col = layout.column(align=True)
    col.alert = alert
    for i, line in enumerate(textwrap.wrap(str(text), chars) or [""]):
        col.label(text=line, icon=icon if i == 0 else 'BLANK1' if icon != 'NONE' else 'NONE')
    return col


# -- Presets ----------------------------------------------------------------------------------
def preset_overrides(settings) -> dict:
    """The settings the chosen preset sets, as ``settings.PRESETS`` has them ({} for Custom)."""
    if settings.preset == 'CUSTOM':
        return {}
    from ..engine.settings import PRESETS
    return dict(PRESETS.get(settings.preset.lower(), {}))


def effective(settings, name: str):
    """The value a render will use: the preset's, else the property's. Enum values come back
    as Blender identifiers ('cache' -> 'CACHE')."""
    fixed = preset_overrides(settings)
    if name not in fixed:
        return getattr(settings, name)
    value = fixed[name]
    return value.upper().replace("-", "_") if isinstance(value, str) else value


def _prop(layout, settings, name: str, fixed: dict, **kwargs):
    """``layout.prop``, greyed out when the preset sets ``name``."""
    if name in fixed:
        layout = layout.column(align=True)
        layout.active = False
    layout.prop(settings, name, **kwargs)


def _indirect_used(settings) -> bool:
    """Full mode with bounces: the Indirect Light settings matter."""
    return settings.mode == 'FULL' and settings.bounces > 0


# -- Render: sampling -------------------------------------------------------------------------
class LANTERNA_RENDER_PT_sampling(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        fixed = preset_overrides(settings)
        layout.prop(settings, "preset")
        layout.prop(settings, "mode")
        col = layout.column(align=True)
        _prop(col, settings, "samples", fixed)
        _prop(col, settings, "noise_threshold", fixed)
        sub = col.column(align=True)
        sub.active = settings.mode == 'FULL'
        _prop(sub, settings, "light_samples", fixed, text="Light Samples")
        layout.prop(settings, "bounces")
        if fixed:
            label = settings.bl_rna.properties["preset"].enum_items[settings.preset].name
            layout.label(text=f"Greyed values are set by the {label} preset", icon='INFO')


class LANTERNA_RENDER_PT_sampling_advanced(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_parent_id = "LANTERNA_RENDER_PT_sampling"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        col = layout.column(align=True)
        col.prop(settings, "seed")
        col.prop(settings, "threads", text="Threads (0 = All Cores)")


class LANTERNA_RENDER_PT_estimate(LanternaRenderPanel, bpy.types.Panel):
    """Issue 6: the estimated time and memory of each stage for the current settings, before
    rendering (``engine/estimate.py``). The scene's facts are cached under a cheap depsgraph
    signature and the estimate recomputed from them at each redraw
    (``engine/blender/live_estimate.py``, ``panel_estimate``)."""
    bl_label = "Estimate"
    bl_parent_id = "LANTERNA_RENDER_PT_sampling"

    def draw(self, context):
        from ..engine.blender.live_estimate import panel_estimate
        from ..engine.estimate import DEFAULT_RATES_PATH, GIB, format_bytes, format_seconds

        layout = self.layout
        estimate, note = panel_estimate(context)
        if estimate is None:
            _wrap(layout, note or "No estimate", context, icon='INFO')
            return
        col = layout.column(align=True)
        for stage in estimate.stages.values():
            if stage.seconds < 0.005 and stage.keeps + stage.working < (1 << 20):
                continue
            row = col.row(align=True)
            row.label(text=stage_title(stage.name))
            row.label(text=format_seconds(stage.seconds))
            row.label(text=format_bytes(stage.keeps + stage.working))
        row = layout.row(align=True)
        row.label(text="Total", icon='TIME')
        row.label(text=format_seconds(estimate.seconds))
        row.label(text=f"peak {format_bytes(estimate.peak_bytes)}")
        available = estimate.available_bytes
        if available is not None and estimate.peak_bytes > available:
            _wrap(layout, f"A render would be refused: it needs about "
                          f"{estimate.peak_bytes / GIB:.1f} GiB, {available / GIB:.1f} GiB is "
                          "available", context, icon='ERROR', alert=True)
        sub = layout.column(align=True)
        sub.active = False
        for text in [note] + list(estimate.warnings):
            if text:
                _wrap(sub, text, context)
        if estimate.rates_source == str(DEFAULT_RATES_PATH):
            _wrap(sub, "Rates: shipped with Lanterna; 'lanterna bench --calibrate' measures "
                       "this machine's", context)
        else:
            _wrap(sub, f"Rates: this machine's ({estimate.rates_source})", context)


# -- Render: photons --------------------------------------------------------------------------
class LANTERNA_RENDER_PT_photons(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Photons"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        fixed = preset_overrides(settings)
        layout.active = settings.mode == 'PHOTON_MAP' or settings.bounces > 0
        _prop(layout, settings, "photons", fixed, text="Photons (0 = Auto)")
        col = layout.column(align=True)
        col.prop(settings, "photon_k")
        col.prop(settings, "photon_radius", text="Max Radius (0 = Auto)")
        layout.prop(settings, "photon_filter")
        layout.prop(settings, "photon_lookups", text="Lookups per Pixel (0 = Auto)")


# -- Render: indirect light -------------------------------------------------------------------
class LANTERNA_RENDER_PT_indirect(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Indirect Light"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        layout.active = _indirect_used(settings)
        _prop(layout, settings, "indirect", preset_overrides(settings), text="Method")
        if settings.mode != 'FULL':
            layout.label(text="Photon Map mode looks the photon map up directly", icon='INFO')
        elif settings.bounces == 0:
            layout.label(text="Max Bounces is 0: direct light only", icon='INFO')


class LANTERNA_RENDER_PT_final_gather(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Final Gather"
    bl_parent_id = "LANTERNA_RENDER_PT_indirect"

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        fixed = preset_overrides(settings)
        method = effective(settings, "indirect")
        layout.active = _indirect_used(settings) and method != 'PHOTON_MAP'
        col = layout.column(align=True)
        _prop(col, settings, "gather_m", fixed, text="Strata Theta (M)")
        _prop(col, settings, "gather_n", fixed, text="Phi (N)")
        layout.prop(settings, "gather_guided")


class LANTERNA_RENDER_PT_irradiance_cache(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Irradiance Cache"
    bl_parent_id = "LANTERNA_RENDER_PT_indirect"

    def draw_header(self, context):
        settings = context.scene.lanterna
        self.layout.active = "indirect" not in preset_overrides(settings)
        self.layout.prop(settings, "use_irradiance_cache", text="")

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        layout.active = _indirect_used(settings) and effective(settings, "indirect") == 'CACHE'
        _prop(layout, settings, "cache_error", preset_overrides(settings), text="Error (a)")
        layout.prop(settings, "cache_gradients")
        layout.prop(settings, "cache_refine")


# -- Render: shadow photons -------------------------------------------------------------------
def area_lights() -> list:
    """The file's area lights in use that carry Lanterna's settings, by name."""
    return sorted((light for light in bpy.data.lights
                   if light.type == 'AREA' and light.users and hasattr(light, "lanterna")),
                  key=lambda light: light.name)


class LANTERNA_RENDER_PT_shadow_photons(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Shadow Photons"

    def draw_header(self, context):
        self.layout.prop(context.scene.lanterna, "shadow_photons", text="")

    def draw(self, context):
        layout = _split(self.layout)
        settings = context.scene.lanterna
        layout.active = settings.shadow_photons and settings.mode == 'FULL'
        if settings.mode != 'FULL':
            layout.label(text="Photon Map mode traces no shadow rays", icon='INFO')
        lights = area_lights()
        if not lights:
            layout.label(text="No area lights (emissive meshes always use them)", icon='INFO')
            return
        col = layout.column(heading="Area Lights", align=True)
        for light in lights[:MAX_LISTED_LIGHTS]:
            col.prop(light.lanterna, "shadow_photons", text=light.name)
        if len(lights) > MAX_LISTED_LIGHTS:
            col.label(text=f"... and {len(lights) - MAX_LISTED_LIGHTS} more")


# -- Render: last render ----------------------------------------------------------------------
STAGE_TITLES = {
    "validate": "Validate", "accel_build": "BVH Build", "lights": "Lights",
    "direct": "Direct Light", "photons": "Photons", "radiance_estimates": "Radiance Estimates",
    "final_gather": "Final Gather", "irradiance_cache": "Irradiance Cache",
    "shadow_photons": "Shadow Photons", "specular": "Specular", "camera": "Camera",
}


def stage_title(name: str) -> str:
    return STAGE_TITLES.get(name, str(name).replace("_", " ").title())


def last_render() -> dict:
    """The RenderEngine's record of the last render (empty before the first)."""
    return session.LAST_RENDER


def plan_rows(report: dict) -> list[tuple[str, bool, str]]:
    """(stage, runs, reason) for every stage of the report's plan, in the plan's order."""
    stages = (report.get("plan") or {}).get("stages") or {}
    rows = []
    for stage, reason in stages.items():
        reason = str(reason)
        skipped = reason.startswith("skipped")
        if skipped:
            reason = reason[len("skipped"):].lstrip(":").strip()
        rows.append((str(stage), not skipped, reason))
    return rows


def stage_times(report: dict):
    """(name, seconds, entry) for each timed stage of the pipeline report, in run order."""
    stages = report.get("stages") or {}
    items = stages.items() if isinstance(stages, dict) else enumerate(stages)
    for key, value in items:
        if isinstance(value, dict):
            name = str(value.get("name", key))
            seconds = value.get("seconds", value.get("time"))
        else:
            name, seconds, value = str(key), value, {}
        if isinstance(seconds, (int, float)):
            yield name, float(seconds), value


def stage_detail(name: str, entry: dict) -> str:
    """A few words on what a stage produced (counts from the report), or ''."""
    def count(key):
        value = entry.get(key)
        return f"{int(value):,}" if isinstance(value, (int, float)) else None

    details = {"photons": ("stored", "stored"), "shadow_photons": ("stored", "photons"),
               "irradiance_cache": ("records", "records"),
               "radiance_estimates": ("estimates", "estimates"),
               "validate": ("triangles", "triangles"), "camera": ("camera_rays", "rays")}
    key, word = details.get(name, (None, None))
    value = count(key) if key else None
    return f"{value} {word}" if value else ""


class LANTERNA_RENDER_PT_last_render(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Last Render"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        last = last_render()
        if not last:
            layout.label(text="No render yet", icon='INFO')
            return
        report = last.get("report") or {}
        if last.get("error"):
            _wrap(layout, last["error"], context, icon='ERROR', alert=True)
        elif last.get("cancelled") or report.get("cancelled"):
            layout.label(text="Cancelled: the picture holds the batches done", icon='CANCEL')
        else:
            layout.label(text="Done", icon='CHECKMARK')
        col = layout.column(align=True)
        size = last.get("size")
        if size:
            text = f"{size[0]} x {size[1]} px"
            border = last.get("border")
            if border:
                text += f", region {border[2] - border[0]} x {border[3] - border[1]} px"
            col.label(text=text)
        settings = report.get("settings") or {}
        if settings:
            col.label(text=f"Mode {settings.get('mode')}, indirect {settings.get('indirect')}, "
                           f"{settings.get('samples')} samples, preset {settings.get('preset')}")
        if isinstance(last.get("total_time"), (int, float)):
            col.label(text=f"Total {last['total_time']:.3f} s")
        summary = (report.get("plan") or {}).get("summary")
        if summary:
            _wrap(layout, summary, context)


class LANTERNA_RENDER_PT_last_render_plan(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Plan"
    bl_parent_id = "LANTERNA_RENDER_PT_last_render"

    def draw(self, context):
        layout = self.layout
        rows = plan_rows(last_render().get("report") or {})
        if not rows:
            layout.label(text="No plan: no render yet, or it stopped before planning")
            return
        for stage, runs, reason in rows:
            col = layout.column(align=True)
            row = col.row()
            row.label(text=stage_title(stage), icon='CHECKMARK' if runs else 'X')
            row.label(text="Runs" if runs else "Skipped")
            sub = col.column(align=True)
            sub.active = False
            _wrap(sub, reason, context)


class LANTERNA_RENDER_PT_last_render_timings(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Timings"
    bl_parent_id = "LANTERNA_RENDER_PT_last_render"

    def draw(self, context):
        layout = self.layout
        last = last_render()
        report = last.get("report") or {}
        rows = []
        if isinstance(last.get("export_seconds"), (int, float)):
            rows.append(("Export", float(last["export_seconds"]), ""))
        rows += [(stage_title(name), seconds, stage_detail(name, entry))
                 for name, seconds, entry in stage_times(report)]
        if not rows:
            layout.label(text="No timings: no render yet, or it failed before the pipeline")
            return
        total = last.get("total_time") or report.get("total_seconds") or 0.0
        col = layout.column(align=True)
        for name, seconds, detail in rows:
            row = col.row(align=True)
            row.label(text=name)
            row.label(text=f"{seconds:.3f} s")
            row.label(text=f"{100.0 * seconds / total:.0f} %" if total > 0 else "")
            row.label(text=detail)
        if total > 0:
            row = layout.row()
            row.label(text="Total")
            row.label(text=f"{total:.3f} s")


class LANTERNA_RENDER_PT_last_render_warnings(LanternaRenderPanel, bpy.types.Panel):
    bl_label = "Warnings"
    bl_parent_id = "LANTERNA_RENDER_PT_last_render"
    bl_options = {'DEFAULT_CLOSED'}

    def draw_header(self, context):
        count = len(last_render().get("warnings") or ())
        self.layout.label(text=str(count) if count else "")

    def draw(self, context):
        layout = self.layout
        warnings = list(last_render().get("warnings") or ())
        if not warnings:
            layout.label(text="None")
            return
        for text in warnings[:MAX_WARNINGS]:
            _wrap(layout, text, context, icon='INFO')
        if len(warnings) > MAX_WARNINGS:
            layout.label(text=f"... and {len(warnings) - MAX_WARNINGS} more")


# -- Material ---------------------------------------------------------------------------------
def _draw_node_input(layout, id_data, input_name: str) -> bool:
    """Draw the node tree feeding ``input_name`` of the active output node; False if none."""
    ntree = getattr(id_data, "node_tree", None)
    if ntree is None:
        return False
    node = ntree.get_output_node('ALL')
    if node is None:
        layout.label(text="No output node")
        return True
    socket = node.inputs.get(input_name)
    if socket is None:
        layout.label(text="Incompatible output node")
        return True
    layout.template_node_view(ntree, node, socket)
    return True


class _SurfacePanel(LanternaPanel):
    """The node tree feeding the Surface input of ``context.<bl_context>`` (a material or the
    world), or ``fallback`` (property, label) when it has no node tree."""

    bl_label = "Surface"
    fallback = ("color", None)

    @classmethod
    def poll(cls, context):
        return getattr(context, cls.bl_context, None) is not None and super().poll(context)

    def draw(self, context):
        layout = _split(self.layout)
        owner = getattr(context, self.bl_context)
        if not _draw_node_input(layout, owner, "Surface"):
            prop, label = self.fallback
            if label:
                layout.prop(owner, prop, text=label)
            else:
                layout.prop(owner, prop)


class LANTERNA_MATERIAL_PT_surface(_SurfacePanel, bpy.types.Panel):
    bl_context = "material"
    fallback = ("diffuse_color", "Base Color")


def channel_sums_over_one(diffuse, specular, tolerance: float = 1e-6) -> list[tuple[str, float]]:
    """(channel, rho_d + rho_s) for each RGB channel where the sum exceeds 1 (+ tolerance)."""
    return [(c, float(d) + float(s)) for c, d, s in zip("RGB", diffuse, specular)
            if float(d) + float(s) > 1.0 + tolerance]


def energy_message(diffuse, specular) -> str:
    """The Radiometry panel's alert: the channels over 1 with their sums; '' when none."""
    over = channel_sums_over_one(diffuse, specular)
    if not over:
        return ""
    sums = ", ".join(f"{c} ({total:.3f})" for c, total in over)
    return f"ρd + ρs > 1 in {sums}: creates energy; the render scales it down"


def _rgb_text(values) -> str:
    """Three numbers for a read-only RGB row: 3 decimals, none from 1000 up."""
    return "  ".join(f"{float(v):.3f}" if abs(float(v)) < 1000 else f"{float(v):,.0f}"
                     for v in values)


def derived_radiometry(material):
    """(core Material, messages) as the render derives them from ``material``'s nodes, or
    (None, [error]) when the node values cannot be rendered."""
    from ..engine.blender.export import material_from_nodes
    from ..engine.scene import SceneError

    messages: list[str] = []
    try:
        return material_from_nodes(material, messages.append), messages
    except SceneError as exc:
        return None, [str(exc)]


class LANTERNA_MATERIAL_PT_radiometry(LanternaPanel, bpy.types.Panel):
    bl_label = "Radiometry"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        mat = context.material
        return mat is not None and hasattr(mat, "lanterna") and super().poll(context)

    def draw(self, context):
        layout = _split(self.layout)
        material = context.material
        settings = material.lanterna
        layout.prop(settings, "derive_from_nodes")
        if settings.derive_from_nodes:
            self.draw_derived(layout, material, context)
            return
        col = layout.column()
        col.prop(settings, "diffuse", text="Diffuse ρd")
        col.prop(settings, "specular", text="Specular ρs")
        col.prop(settings, "exitance", text="Exitance M (W/m²)")
        message = energy_message(settings.diffuse, settings.specular)
        if message:
            _wrap(layout, message, context, icon='ERROR', alert=True)

    @staticmethod
    def draw_derived(layout, material, context):
        derived, messages = derived_radiometry(material)
        box = layout.box()
        box.label(text="From the node tree (what the render uses)", icon='NODETREE')
        if derived is None:
            _wrap(box, messages[0], context, icon='ERROR', alert=True)
            return
        col = box.column(align=True)
        for name, values in (("Diffuse ρd", derived.diffuse), ("Specular ρs", derived.specular),
                             ("Exitance M (W/m²)", derived.exitance)):
            row = col.row()
            row.label(text=name)
            row.label(text=_rgb_text(values))
        lobes = lobe_names(derived.closures)
        if lobes:
            box.label(text="Lobes in Cycles' terms: " + ", ".join(lobes))
        for text in messages[:6]:
            _wrap(box, text, context, icon='INFO')


# -- Light ------------------------------------------------------------------------------------
class LANTERNA_LIGHT_PT_light(LanternaPanel, bpy.types.Panel):
    bl_label = "Light"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.light is not None and super().poll(context)

    def draw(self, context):
        layout = self.layout
        light = context.light
        layout.row().prop(light, "type", expand=True)
        _split(layout)
        col = layout.column()
        col.prop(light, "color")
        col.prop(light, "energy")
        col = layout.column()
        if light.type in {'POINT', 'SPOT'}:
            col.prop(light, "shadow_soft_size", text="Radius")
        elif light.type == 'SUN':
            col.prop(light, "angle")
        elif light.type == 'AREA':
            col.prop(light, "shape")
            sub = col.column(align=True)
            if light.shape in {'SQUARE', 'DISK'}:
                sub.prop(light, "size")
            else:
                sub.prop(light, "size", text="Size X")
                sub.prop(light, "size_y", text="Y")
            if hasattr(light, "spread"):
                col.prop(light, "spread")
        if light.type == 'SPOT':
            col = layout.column()
            col.prop(light, "spot_size", text="Spot Size")
            col.prop(light, "spot_blend", text="Blend", slider=True)
            col.prop(light, "show_cone")


def shadow_photon_note(light, scene_settings) -> str:
    """Why ``light``'s shadow-photon switch does nothing, or '' when it counts."""
    if light.type != 'AREA':
        return f"{light.type.title()} lights cast hard shadows with one ray; no shadow photons"
    from ..engine.blender.export import COLLIMATED_SPREAD
    if getattr(light, "spread", math.pi) < COLLIMATED_SPREAD:
        return "Spread 0: a directional light with one shadow ray; no shadow photons"
    if scene_settings is not None and not scene_settings.shadow_photons:
        return "Shadow photons are off for the scene (Render > Shadow Photons)"
    return ""


class LANTERNA_LIGHT_PT_photons(LanternaPanel, bpy.types.Panel):
    bl_label = "Photons"
    bl_context = "data"
    bl_parent_id = "LANTERNA_LIGHT_PT_light"

    @classmethod
    def poll(cls, context):
        light = context.light
        return light is not None and hasattr(light, "lanterna") and super().poll(context)

    def draw(self, context):
        layout = _split(self.layout)
        light = context.light
        settings = light.lanterna
        layout.prop(settings, "photon_share")
        if settings.photon_share == 0:
            layout.label(text="Sends no photons: adds no indirect light", icon='INFO')
        scene = getattr(context, "scene", None)
        note = shadow_photon_note(light, getattr(scene, "lanterna", None))
        col = layout.column()
        col.active = not note
        col.prop(settings, "shadow_photons")
        if note:
            _wrap(layout, note, context, icon='INFO')


# -- World ------------------------------------------------------------------------------------
class LANTERNA_CAMERA_PT_panorama(LanternaPanel, bpy.types.Panel):
    """Blender's Lens panel draws a panoramic camera's projection for Cycles only: the same
    settings, and what Lanterna renders of them."""
    bl_label = "Panorama"
    bl_context = "data"
    bl_parent_id = "DATA_PT_lens"

    @classmethod
    def poll(cls, context):
        camera = getattr(context, "camera", None)
        return super().poll(context) and camera is not None and camera.type == 'PANO'

    def draw(self, context):
        layout = _split(self.layout)
        camera = context.camera
        layout.prop(camera, "panorama_type")
        if camera.panorama_type == 'EQUIRECTANGULAR':
            sub = layout.column(align=True)
            sub.prop(camera, "latitude_min", text="Latitude Min")
            sub.prop(camera, "latitude_max", text="Max")
            sub = layout.column(align=True)
            sub.prop(camera, "longitude_min", text="Longitude Min")
            sub.prop(camera, "longitude_max", text="Max")
        else:
            _wrap(layout, "Lanterna renders only the equirectangular projection; this one is "
                  "rendered as a perspective camera (the render reports it).", context,
                  icon='INFO')


class LANTERNA_WORLD_PT_surface(_SurfacePanel, bpy.types.Panel):
    bl_context = "world"


# -- View layer: passes ------------------------------------------------------------------------
class LANTERNA_VIEW_LAYER_PT_passes(LanternaPanel, bpy.types.Panel):
    bl_label = "Passes"
    bl_context = "view_layer"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = context.view_layer.lanterna_passes
        col = layout.column(heading="Light", align=True)
        for prop in ("direct", "indirect", "emission"):
            col.prop(settings, prop)
        col = layout.column(heading="Method", align=True)
        for prop in ("photon_map", "photons", "cache_points", "cache_usage", "shadow_classes"):
            col.prop(settings, prop)
        # Cycles' light passes: Blender's own view-layer flags (ui/render_passes.py).
        view_layer = context.view_layer
        for heading, word in (("Diffuse", "diffuse"), ("Glossy", "glossy"),
                              ("Transmission", "transmission")):
            row = layout.row(heading=heading, align=True)
            for part, label in (("direct", "Direct"), ("indirect", "Indirect"),
                                ("color", "Color")):
                row.prop(view_layer, f"use_pass_{word}_{part}", text=label, toggle=True)
        col = layout.column(heading="Other", align=True)
        col.prop(view_layer, "use_pass_emit", text="Emission")
        col.prop(view_layer, "use_pass_environment", text="Environment")



classes = (
    LANTERNA_RENDER_PT_sampling,
    LANTERNA_RENDER_PT_sampling_advanced,
    LANTERNA_RENDER_PT_estimate,
    LANTERNA_RENDER_PT_photons,
    LANTERNA_RENDER_PT_indirect,
    LANTERNA_RENDER_PT_final_gather,
    LANTERNA_RENDER_PT_irradiance_cache,
    LANTERNA_RENDER_PT_shadow_photons,
    LANTERNA_RENDER_PT_last_render,
    LANTERNA_RENDER_PT_last_render_plan,
    LANTERNA_RENDER_PT_last_render_timings,
    LANTERNA_RENDER_PT_last_render_warnings,
    LANTERNA_MATERIAL_PT_surface,
    LANTERNA_MATERIAL_PT_radiometry,
    LANTERNA_LIGHT_PT_light,
    LANTERNA_LIGHT_PT_photons,
    LANTERNA_CAMERA_PT_panorama,
    LANTERNA_WORLD_PT_surface,
    LANTERNA_VIEW_LAYER_PT_passes,
)


# -- Blender's own panels ---------------------------------------------------------------------
# Wanted whatever their COMPAT_ENGINES say: output, colour management, camera (with its depth
# of field), material slots, light and world data blocks.
_EXTRA_BUILTINS = {
    "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_stamp",
    "RENDER_PT_color_management", "RENDER_PT_color_management_curves",
    "DATA_PT_context_camera", "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_camera_display",
    "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture",
    "DATA_PT_context_light", "WORLD_PT_context_world", "EEVEE_MATERIAL_PT_context_material",
}
# BLENDER_RENDER panels that Lanterna replaces with its own or that cannot work for it: the
# light panel (LANTERNA_LIGHT_PT_light draws the same and the spot cone), its Beam Shape
# sub-panel (parented to EEVEE's light panel), and the previews (no preview renders).
_EXCLUDED_BUILTINS = {"DATA_PT_light", "DATA_PT_spot", "DATA_PT_preview",
                      "MATERIAL_PT_preview", "WORLD_PT_context_world_preview"}

_opened: list[type] = []  # built-in panels whose COMPAT_ENGINES we extended


def _all_panels() -> list[type]:
    """Every Panel class Python knows, subclasses of subclasses included."""
    found, todo, seen = [], list(bpy.types.Panel.__subclasses__()), set()
    while todo:
        panel = todo.pop()
        if panel in seen:
            continue
        seen.add(panel)
        found.append(panel)
        todo.extend(panel.__subclasses__())
    return found


def builtin_panels() -> list[type]:
    """Blender's panels to open to Lanterna: own set lists BLENDER_RENDER, or named extras.

    Some panels share one set object (the node editor's copies of the light panels share the
    Properties editor's); a panel whose set is also an excluded panel's set is left alone.
    """
    panels = _all_panels()
    excluded_sets = [p.__dict__["COMPAT_ENGINES"] for p in panels
                     if p.__name__ in _EXCLUDED_BUILTINS and "COMPAT_ENGINES" in p.__dict__]
    found = []
    for panel in panels:
        name = panel.__name__
        engines = panel.__dict__.get("COMPAT_ENGINES")  # own set only, never an inherited one
        if not isinstance(engines, set) or name.startswith("LANTERNA_"):
            continue
        if name in _EXCLUDED_BUILTINS or any(engines is s for s in excluded_sets):
            continue
        if "BLENDER_RENDER" in engines or name in _EXTRA_BUILTINS:
            found.append(panel)
    return found


def register():
    from ..engine.blender.classes import register_classes
    register_classes(classes)
    for panel in builtin_panels():
        if ENGINE_ID not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE_ID)
            _opened.append(panel)


def unregister():
    while _opened:
        _opened.pop().COMPAT_ENGINES.discard(ENGINE_ID)
    # Also any set an earlier copy of this module opened (a reload loses ``_opened``).
    for panel in _all_panels():
        engines = panel.__dict__.get("COMPAT_ENGINES")
        if isinstance(engines, set) and not panel.__name__.startswith("LANTERNA_"):
            engines.discard(ENGINE_ID)
    from ..engine.blender.classes import unregister_classes
    unregister_classes(classes)
