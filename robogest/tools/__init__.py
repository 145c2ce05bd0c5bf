"""Robot tools: what a person runs on a robot definition, above the stages it uses.

:mod:`.validate` checks a robot YAML against its MuJoCo model, its servos and the retargeter
(``robogest robots validate``); :mod:`.importer` makes a robot from a URDF, xacro or MJCF description
(``robogest robots import``); :mod:`.lerobot_calibration` writes a calibrated copy of a robot YAML
(``robogest robots import-lerobot-calibration``). They sit above retargeting and the backends, which they call;
:mod:`robogest.robot` below keeps the schema, the registry, the MJCF loader and the YAML writer.
"""
