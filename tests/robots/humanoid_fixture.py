"""A small floating-base humanoid written by the tests: the shape of an imported one (a menagerie-style MJCF with a
free-floating pelvis), small enough to retarget and simulate in seconds.

``write_humanoid(folder)`` writes ``<folder>/minihuman.xml`` and ``<folder>/minihuman.yaml`` and returns the YAML
path. The MJCF: a pelvis on a free joint; two legs (hip pitch/roll, knee, ankle); waist yaw; neck pan/tilt; two arms
(shoulder pitch/roll, elbow, 2-DoF wrist); retargeting sites; one position actuator per joint; a ``home`` keyframe
standing with the feet on the floor (pelvis at :data:`STAND_HEIGHT_M`). The YAML holds the legs (``held: true``)
and has a Feetech bus section (ids 1.., STS3215). Reusable by other tests (the URDF importer's end-to-end tests).
"""

from __future__ import annotations

from pathlib import Path

import yaml

#: Pelvis height in the home keyframe: the soles touch z = 0 there (hip 0.04 + thigh 0.22 + shin 0.22 + foot 0.04).
STAND_HEIGHT_M = 0.52
#: Joint order of the YAML, with the MJCF range and the rest angle of each (radians).
JOINTS = {
    "l_hip_pitch": (-1.5, 1.0, 0.0), "l_hip_roll": (-0.5, 0.5, 0.0), "l_knee": (0.0, 2.0, 0.0),
    "l_ankle": (-0.8, 0.8, 0.0),
    "r_hip_pitch": (-1.5, 1.0, 0.0), "r_hip_roll": (-0.5, 0.5, 0.0), "r_knee": (0.0, 2.0, 0.0),
    "r_ankle": (-0.8, 0.8, 0.0),
    "waist_yaw": (-1.0, 1.0, 0.0), "neck_pan": (-1.2, 1.2, 0.0), "neck_tilt": (-0.6, 0.5, 0.0),
    "l_shoulder_pitch": (-1.0, 2.8, 0.0), "l_shoulder_roll": (-0.1, 2.2, 0.1), "l_elbow": (0.0, 2.2, 0.3),
    "l_wrist_pitch": (-1.0, 1.0, 0.0), "l_wrist_roll": (-1.0, 1.0, 0.0),
    "r_shoulder_pitch": (-1.0, 2.8, 0.0), "r_shoulder_roll": (-0.1, 2.2, 0.1), "r_elbow": (0.0, 2.2, 0.3),
    "r_wrist_pitch": (-1.0, 1.0, 0.0), "r_wrist_roll": (-1.0, 1.0, 0.0),
}  # fmt: skip
LEGS = [n for n in JOINTS if n.split("_", 1)[1] in ("hip_pitch", "hip_roll", "knee", "ankle")]
ARMS = {s: [n for n in JOINTS if n.startswith(f"{s}_") and n not in LEGS] for s in ("l", "r")}

_LEG = """
      <body name="{s}_thigh" pos="0 {y} -0.04">
        <joint name="{s}_hip_pitch" axis="0 1 0" range="{r[l_hip_pitch]}"/>
        <joint name="{s}_hip_roll" axis="1 0 0" range="{r[l_hip_roll]}"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.22" size="0.03" mass="0.8"/>
        <body name="{s}_shin" pos="0 0 -0.22">
          <joint name="{s}_knee" axis="0 1 0" range="{r[l_knee]}"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.22" size="0.025" mass="0.5"/>
          <body name="{s}_foot" pos="0 0 -0.22">
            <joint name="{s}_ankle" axis="0 1 0" range="{r[l_ankle]}"/>
            <geom name="{s}_sole" type="box" size="0.07 0.035 0.02" pos="0.03 0 -0.02" mass="0.2"/>
          </body>
        </body>
      </body>"""

_ARM = """
        <body name="{s}_upper_arm" pos="0 {y} 0.28">
          <joint name="{s}_shoulder_pitch" axis="0 -1 0" range="{r[l_shoulder_pitch]}"/>
          <joint name="{s}_shoulder_roll" axis="{roll} 0 0" range="{r[l_shoulder_roll]}"/>
          <site name="{s}_shoulder_site" size="0.01"/>
          <geom type="capsule" fromto="0 0 -0.02 0 0 -0.15" size="0.022" mass="0.2"/>
          <body name="{s}_forearm" pos="0 0 -0.15">
            <joint name="{s}_elbow" axis="0 -1 0" range="{r[l_elbow]}"/>
            <site name="{s}_elbow_site" size="0.01"/>
            <geom type="capsule" fromto="0 0 -0.02 0 0 -0.13" size="0.02" mass="0.15"/>
            <body name="{s}_hand" pos="0 0 -0.13">
              <joint name="{s}_wrist_pitch" axis="0 -1 0" range="{r[l_wrist_pitch]}"/>
              <joint name="{s}_wrist_roll" axis="1 0 0" range="{r[l_wrist_roll]}"/>
              <site name="{s}_wrist_site" size="0.01"/>
              <geom type="box" size="0.012 0.03 0.035" pos="0 0 -0.04" mass="0.05"/>
              <site name="{s}_hand_site" pos="0 0 -0.07" size="0.01"/>
            </body>
          </body>
        </body>"""


def mjcf(*, home: bool = True, stand_height_m: float = STAND_HEIGHT_M) -> str:
    """The model's XML; ``home=False`` leaves out the keyframe (the loader then sets the feet on the floor)."""
    r = {n: f"{lo} {hi}" for n, (lo, hi, _) in JOINTS.items()}
    legs = _LEG.format(s="l", y=0.08, r=r) + _LEG.format(s="r", y=-0.08, r=r)
    arms = _ARM.format(s="l", y=0.15, roll=1, r=r) + _ARM.format(s="r", y=-0.15, roll=-1, r=r)
    acts = "\n".join(f'    <position name="{n}" joint="{n}" kp="20" kv="0.5" inheritrange="1" forcerange="-8 8"/>'
                     for n in JOINTS)  # fmt: skip
    rest = " ".join(f"{v[2]:g}" for v in JOINTS.values())
    key = (f'  <keyframe><key name="home" qpos="0 0 {stand_height_m} 1 0 0 0 {rest}" ctrl="{rest}"/></keyframe>'
           if home else "")  # fmt: skip
    return f"""<mujoco model="minihuman">
  <compiler angle="radian"/>
  <option timestep="0.002"/>
  <default><joint type="hinge" damping="0.6" armature="0.01"/></default>
  <worldbody>
    <light pos="0.8 0.3 2" dir="-0.4 -0.1 -1" directional="true"/>
    <geom name="floor" type="plane" size="0 0 0.05" rgba="0.3 0.35 0.4 1"/>
    <body name="pelvis" pos="0 0 0.9">
      <freejoint name="root"/>
      <geom type="box" size="0.06 0.11 0.04" mass="2"/>{legs}
      <body name="torso" pos="0 0 0.05">
        <joint name="waist_yaw" axis="0 0 1" range="{r["waist_yaw"]}"/>
        <geom type="box" size="0.06 0.1 0.14" pos="0 0 0.15" mass="3"/>
        <body name="head" pos="0 0 0.33">
          <joint name="neck_pan" axis="0 0 1" range="{r["neck_pan"]}"/>
          <joint name="neck_tilt" axis="0 -1 0" range="{r["neck_tilt"]}"/>
          <geom type="sphere" size="0.06" pos="0 0 0.07" mass="0.5"/>
          <site name="head_site" pos="0 0 0.07" size="0.01"/>
          <site name="nose_site" pos="0.05 0 0.11" size="0.01"/>
        </body>{arms}
      </body>
    </body>
  </worldbody>
  <actuator>
{acts}
  </actuator>
{key}
</mujoco>
"""


def robot_yaml(*, held: list[str] | None = None, model: str = "minihuman.xml", bus: bool = True) -> dict:
    """The robot definition as a dict: ``held`` joints (default the legs) held, the rest gesturing."""
    held = LEGS if held is None else held
    joints = [{"name": n, "lower_rad": lo, "upper_rad": hi, "max_velocity_rad_s": 3.0, "max_acceleration_rad_s2": 20.0,
               "rest_rad": rest, **({"held": True} if n in held else {})}
              for n, (lo, hi, rest) in JOINTS.items()]  # fmt: skip
    vectors = [{"human": ["r_shoulder", "l_shoulder"], "robot": ["r_shoulder_site", "l_shoulder_site"], "weight": 0.5},
               {"human": ["head", "nose"], "robot": ["head_site", "nose_site"], "weight": 0.7}]  # fmt: skip
    for s in ("l", "r"):
        vectors += [
            {"human": [f"{s}_shoulder", f"{s}_elbow"], "robot": [f"{s}_shoulder_site", f"{s}_elbow_site"]},
            {"human": [f"{s}_elbow", f"{s}_wrist"], "robot": [f"{s}_elbow_site", f"{s}_wrist_site"]},
            {"human": [f"{s}_wrist", f"{s}_hand"], "robot": [f"{s}_wrist_site", f"{s}_hand_site"], "weight": 0.3},
        ]
    out = {"name": "minihuman", "description": "test humanoid, floating base, legs held", "model": model,
           "joints": joints, "retarget": vectors}  # fmt: skip
    if bus:
        out["bus"] = {"family": "feetech", "protocol": 0, "baudrate": 1_000_000,
                      "servos": {n: {"id": k + 1, "model": "STS3215"} for k, n in enumerate(JOINTS)}}  # fmt: skip
    return out


def write_humanoid(folder: str | Path, *, home: bool = True, **yaml_options: object) -> Path:
    """Write ``minihuman.xml`` and ``minihuman.yaml`` into ``folder``; returns the YAML path (options: :func:`mjcf`,
    :func:`robot_yaml`)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "minihuman.xml").write_text(mjcf(home=home))
    path = folder / "minihuman.yaml"
    path.write_text(yaml.safe_dump(robot_yaml(**yaml_options), sort_keys=False))
    return path
