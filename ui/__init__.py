"""User interface: ``properties`` (PropertyGroups under ``Scene/Material/Light.lanterna``) and
``panels`` (Properties-editor panels). Registered by ``engine.blender.registration``."""
