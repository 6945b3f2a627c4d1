"""The pipeline: runs the stages in a fixed order, times each and fills the report.

(Placeholder while the stages land; the signature below is the contract.)
"""
from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np


@dataclass
class RenderSettings:
    samples: int = 16          # camera samples per pixel
    light_samples: int = 4     # area / mesh / world light samples per camera hit
    bounces: int = 0           # indirect bounces; 0 = direct light only
    seed: int = 0
    threads: int = 2
    filter_width: float = 1.5  # pixels, Blackman-Harris


@dataclass
class RenderResult:
    image: np.ndarray                      # (H, W, 3) float32 linear radiance, row 0 = top
    passes: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)
    cancelled: bool = False


def render(scene, settings=None, progress=None, cancelled=None) -> RenderResult:
    """Render ``scene``; ``progress(fraction, text)`` is called between batches and
    ``cancelled()`` is polled there (return True to stop early)."""
    settings = settings or RenderSettings()
    w, h = scene.camera.window_size
    return RenderResult(image=np.zeros((h, w, 3), np.float32), report={"stages": {}})
