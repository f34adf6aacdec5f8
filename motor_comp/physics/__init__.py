"""Physics core (numpy + numba only, never rclpy): effects, axis model, plant kernel."""
from __future__ import annotations

from motor_comp.physics.axis import AxisModel, InputKind
from motor_comp.physics.config import PlantConfig, PlantKind, ballscrew_model, load_plant, \
    plant_from_dict, pmlm_model
from motor_comp.physics.effects import EFFECTS, VOCABULARY, Effect, EffectKind, make_effect
from motor_comp.physics.plant import Measurement, Plant, Sensors, StepLoad

__all__ = ['AxisModel', 'InputKind', 'PlantConfig', 'PlantKind', 'ballscrew_model',
           'load_plant', 'plant_from_dict', 'pmlm_model', 'EFFECTS', 'VOCABULARY', 'Effect',
           'EffectKind', 'make_effect', 'Measurement', 'Plant', 'Sensors', 'StepLoad']
