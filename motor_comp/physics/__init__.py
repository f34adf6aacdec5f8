"""Physics core (numpy + numba only, never rclpy): effects, axis model, plant kernel."""
from __future__ import annotations

from motor_comp.physics._jitcache import refresh_stale_caches

refresh_stale_caches()  # before any kernel is loaded from the numba cache

from motor_comp.physics.axis import AxisKind, AxisModel, InputKind, Units  # noqa: E402
from motor_comp.physics.config import PlantConfig, PlantKind, ballscrew_model, \
    load_plant, plant_from_dict, pmlm_model  # noqa: E402
from motor_comp.physics.effects import EFFECTS, VOCABULARY, Effect, EffectKind, \
    make_effect  # noqa: E402
from motor_comp.physics.plant import Measurement, Plant, Sensors, StepLoad  # noqa: E402

__all__ = ['AxisKind', 'AxisModel', 'InputKind', 'Units', 'PlantConfig', 'PlantKind',
           'ballscrew_model', 'load_plant', 'plant_from_dict', 'pmlm_model', 'EFFECTS',
           'VOCABULARY', 'Effect', 'EffectKind', 'make_effect', 'Measurement', 'Plant',
           'Sensors', 'StepLoad']
