"""Lanterna's benchmarks and calibration: measurements, never tests (the machine is shared, so
each prints ratios against a baseline measured in the same run). Not part of the add-on: the
extension zips leave this folder out, and ``lanterna bench`` finds it only in a checkout.

    ``main.py``              ``lanterna bench``: prints ``throughput.py``'s figures (stage
                             times, rays against raw embreex in ``raw_embree.py``, export
                             speed, photons, kd-tree look-ups); hands the flags below to
                             their modules
    ``calibrate.py``         ``--calibrate`` / ``--check-estimate``: this machine's rates for
                             the cost estimate (``engine/estimate.py``) and their check
    ``sweep.py``             ``--sweep``: quality settings against a reference and Cycles
    ``vs_cycles.py``         ``--vs-cycles``: the ``final`` preset against Cycles
    ``materials.py``         ``--materials``: ``final``'s time against Cycles' at the same
                             error on the material scenes (issue 23)
    ``texture_cost.py``      ``--textures``: what texture evaluation adds to the textured
                             room's ``final`` against its textures' means (issue 24)
    ``floor_sharpness.py``   ``--sharpness``: the textured room's floor against a plain one,
                             blur or noise (issue 24)
    ``hair_vs_cycles.py``    ``--hair``: a fur ball's ``final`` against Cycles' 3D curves
    ``cache_index.py``       ``--cache-index``: the irradiance cache's grid against its kd-tree
    ``validation.py``        ``--validation``: writes docs/validation.md
    ``performance.py``       ``--performance``: writes docs/performance.md (runs the sweep)
    ``fit_cache_counts.py``  refits the estimate's irradiance-cache counts from renders
"""
