"""`robogest robots import` on humanoids: the body parts found from the kinematic tree, the forward direction, messy
descriptions, xacro and MJCF, and the whole path import -> validate -> speak --save with both arms moving and the
legs still. Every description is synthetic, written by tests/robots/humanoids.py."""

from __future__ import annotations

import re

import mujoco
import numpy as np
import pytest
import yaml

from robogest.cli.main import main
from robogest.robot.config import load_robot_config
from robogest.tools.importer import import_description
from robogest.trajectory import Trajectory
from tests.robots.humanoids import ARM, LEG, Options, write_mjcf, write_urdf, write_xacro

pytest.importorskip("trimesh")


def _parts(res) -> dict[str, list[str]]:
    return {part: joints for part, joints, _ in res.parts.rows}


def _home(robot):
    m = mujoco.MjModel.from_xml_path(str(robot.model_path))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home"))
    mujoco.mj_forward(m, d)
    return m, d


@pytest.fixture(scope="module")
def messy(tmp_path_factory):
    """Floating base, gripper, upper-case mesh names, reversed knee range, zero velocity/effort and inertia,
    gazebo/transmission elements, a fixed IMU link, Dynamixel model names in the link names."""
    d = tmp_path_factory.mktemp("messy")
    o = Options(gripper=True, hand_mesh="STL", floating=True, messy=True, servo="XM430")
    return import_description(write_urdf(d, o), d / "robots" / "toy.yaml")


def test_parts_come_from_the_tree(messy):
    parts = _parts(messy)
    assert parts["left leg"] == [f"left_{j}" for j in LEG] and parts["right leg"] == [f"right_{j}" for j in LEG]
    assert parts["left arm"] == [f"left_{j}" for j in ARM] and parts["right arm"] == [f"right_{j}" for j in ARM]
    assert parts["head"] == ["neck_yaw", "neck_pitch"] and parts["waist"] == ["waist_yaw", "waist_roll"]
    assert parts["fingers/eyes/jaw"] == ["left_gripper", "right_gripper"]
    robot = load_robot_config(messy.yaml_path)
    held = {j.name for j in robot.joints if j.held}
    assert held == {f"{s}_{j}" for s in ("left", "right") for j in LEG} | {"waist_yaw", "waist_roll"} | {
        "left_gripper", "right_gripper"}  # fmt: skip
    rest = {j.name: j.rest_rad for j in robot.joints}
    assert rest["left_knee"] == rest["right_knee"] == 0.0, "knees straight at rest, not bent to mid-range"
    assert rest["left_elbow"] < -0.1 and rest["right_elbow"] < -0.1, "elbows a little bent"
    # the import record (read back on re-import) and the bus proposal from the Dynamixel names
    raw = yaml.safe_load(messy.yaml_path.read_text())
    assert raw["import"]["arms"]["left"] == [f"left_{j}" for j in ARM] and raw["import"]["head"] == parts["head"]
    assert "family: dynamixel" in messy.yaml_path.read_text() and "model: XM430" in messy.yaml_path.read_text()


def test_messy_description_is_repaired_with_warnings(messy):
    text = "\n".join(messy.guesses)
    for needle in ("lower above upper", "no velocity limit", "zero mass or zero inertia", "gazebo/transmission",
                   "differ in case", "base floats", "no effort limit"):  # fmt: skip
        assert needle in text, needle
    robot = load_robot_config(messy.yaml_path)
    knee = next(j for j in robot.joints if j.name == "left_knee")
    assert (knee.lower_rad, knee.upper_rad) == pytest.approx((-0.1, 2.2))


def test_stands_on_the_floor_facing_x(messy):
    robot = load_robot_config(messy.yaml_path)
    m, d = _home(robot)
    # the soles (2 cm boxes 4 cm below the ankles) on the floor: the ankles 5 cm above it
    assert d.xanchor[m.joint("left_ankle").id][2] == pytest.approx(0.05, abs=1e-3), "feet on the floor"
    site = {m.site(i).name: d.site_xpos[i] for i in range(m.nsite)}
    assert site["l_shoulder_site"][1] > 0.1 > -0.1 > site["r_shoulder_site"][1], "left on +Y: faces +X"
    assert site["face_site"][0] > site["head_site"][0] + 0.01, "the face is in front"
    assert site["l_hand_site"][2] < site["l_elbow_site"][2] < site["l_shoulder_site"][2], "arms hang at rest"


def test_y_forward_description_is_turned(tmp_path):
    res = import_description(write_urdf(tmp_path, Options(forward="y", arm_dof=3)), tmp_path / "robots" / "y.yaml")
    assert any("faces +y" in g and "turned -90 deg" in g for g in res.guesses)
    m, d = _home(load_robot_config(res.yaml_path))
    site = {m.site(i).name: d.site_xpos[i] for i in range(m.nsite)}
    assert site["l_shoulder_site"][1] > 0.1 and abs(site["l_shoulder_site"][0]) < 0.02
    assert _parts(res)["left arm"] == ["left_shoulder_pitch", "left_shoulder_roll", "left_elbow", "left_wrist_pitch",
                                       "left_wrist_roll"]  # fmt: skip


def test_overrides_are_kept_on_reimport(tmp_path):
    """--arm/--head/--forward go into the import record; importing again (--force) without them keeps them."""
    urdf = write_urdf(tmp_path, Options(arm_dof=3))
    out = tmp_path / "robots" / "o.yaml"
    arms = {"left": ["left_shoulder_pitch", "left_shoulder_roll", "left_elbow"],
            "right": ["right_shoulder_pitch", "right_shoulder_roll", "right_elbow"]}  # fmt: skip
    hold = {"waist_yaw": 0.2, "left_shoulder_roll": 0.3}
    import_description(urdf, out, overrides={"arms": arms, "head": ["neck_yaw"], "hold": hold})
    res = import_description(urdf, out, overwrite=True)
    assert _parts(res)["left arm"] == arms["left"] and _parts(res)["head"] == ["neck_yaw"]
    robot = load_robot_config(out)
    rest = {j.name: (j.rest_rad, j.held) for j in robot.joints}
    assert rest["waist_yaw"] == (0.2, True) and rest["left_wrist_pitch"][1] and rest["neck_pitch"][1]
    assert rest["left_shoulder_roll"] == (0.3, True), "an arm joint held with --hold"
    assert robot.import_record.hold == hold


def test_an_elbow_bending_sideways_at_zero_rests_bent_forward(tmp_path):
    """The elbow's axis points forward at joint zero (it bends sideways there, as ToddlerBot's does); the upper-arm
    twist must turn for it to bend forward as a person's does, and the import still validates."""
    from robogest.tools.validate import validate

    res = import_description(write_urdf(tmp_path, Options(sideways_elbow=True)), tmp_path / "robots" / "s.yaml")
    assert [str(p) for p in validate(res.yaml_path)] == []
    rest = {j.name: j.rest_rad for j in load_robot_config(res.yaml_path).joints}
    assert abs(rest["left_upper_arm_yaw"]) > 0.3 and abs(rest["right_upper_arm_yaw"]) > 0.3


def test_mjcf_in_degrees_with_meshes_named_after_their_files(tmp_path):
    """An MJCF without ``angle="radian"`` gives its ranges in degrees; the ranges the import writes with its servos
    (and its sites and keyframe) are radians, so the model is written back in radians and its limits come out
    right. Its ``<mesh file="hand.stl"/>`` is named "hand" by MuJoCo and still found under its copy's name."""
    from robogest.tools.validate import validate

    res = import_description(
        write_mjcf(tmp_path, Options(arm_dof=3, hand_mesh="stl"), degrees=True, actuators=False),
        tmp_path / "robots" / "d.yaml",
    )
    elbow = next(j for j in load_robot_config(res.yaml_path).joints if j.name == "left_elbow")
    assert (elbow.lower_rad, elbow.upper_rad) == pytest.approx((-2.2, 0.1), abs=1e-5)
    assert len(list((res.mjcf_path.parent / "assets").iterdir())) == 1
    assert [str(p) for p in validate(res.yaml_path)] == []


def _speak(tmp_path, desc, capsys) -> tuple[np.ndarray, object]:
    out = tmp_path / "robots" / "bot.yaml"
    assert main(["robots", "import", str(desc), "--out", str(out)]) == 0, capsys.readouterr().err
    table = capsys.readouterr().out
    assert "left arm" in table and "right leg" in table and f"{out}: valid" in table
    assert main(["robots", "validate", str(out)]) == 0
    save = tmp_path / "s.npz"
    say = "Hello! I am glad to meet you. Look over there, and then we can start."
    assert main(["speak", say, "--robot", str(out), "--save", str(save)]) == 0
    robot = load_robot_config(out)
    ptp = dict(zip(robot.joint_names, np.ptp(Trajectory.load(save).q_rad, axis=0), strict=True))
    return ptp, robot


@pytest.mark.slow
@pytest.mark.parametrize(
    "kind",
    ["urdf-x-gripper", "urdf-y-dae", "xacro", "mjcf"],
)
def test_import_validate_speak(tmp_path, capsys, kind):
    """Through the CLI: import -> validate -> speak --save; some joint of each arm moves >= 0.3 rad, every leg joint
    (and every other held joint) <= 0.02 rad, the head moves."""
    if kind == "urdf-x-gripper":
        desc = write_urdf(tmp_path, Options(gripper=True, hand_mesh="STL", floating=True))
    elif kind == "urdf-y-dae":
        desc = write_urdf(tmp_path, Options(forward="y", arm_dof=3, hand_mesh="dae"))
    elif kind == "xacro":
        pytest.importorskip("xacro")
        desc = write_xacro(tmp_path, Options(arm_dof=3))
    else:
        desc = write_mjcf(tmp_path, Options())
    ptp, robot = _speak(tmp_path, desc, capsys)
    for side in ("left", "right"):
        assert max(ptp[j] for j in robot.import_record.arms[side]) >= 0.3, side
        assert max(ptp[f"{side}_{j}"] for j in LEG) <= 0.02
    assert max(ptp[j.name] for j in robot.joints if j.held) <= 0.02, "waist, legs and gripper still"
    assert max(ptp["neck_yaw"], ptp["neck_pitch"]) > 0.05
    assert robot.import_record is not None


def test_xacro_without_the_extra_is_exit_6_with_the_pip_command(tmp_path, monkeypatch, capsys):
    import sys

    desc = write_xacro(tmp_path, Options(arm_dof=3))
    monkeypatch.setitem(sys.modules, "xacro", None)  # not installed
    assert main(["robots", "import", str(desc), "--out", str(tmp_path / "out" / "x.yaml")]) == 6
    assert re.search(r"pip install -e '.*\[import\]'", capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


def test_cli_map_file_and_bad_override(tmp_path, capsys):
    desc = write_urdf(tmp_path, Options(arm_dof=3))
    m = tmp_path / "map.yaml"
    m.write_text("head: [neck_pitch]\nforward: '+x'\n")
    out = tmp_path / "robots" / "m.yaml"
    assert main(["robots", "import", str(desc), "--out", str(out), "--map", str(m)]) == 0
    assert load_robot_config(out).import_record.head == ["neck_pitch"]
    assert main(["robots", "import", str(desc), "--out", str(out), "--force", "--arm", "middle=a,b"]) == 2
    assert "--arm middle=a,b: write --arm left=J1,J2,..." in capsys.readouterr().err
    assert main(["robots", "import", str(desc), "--out", str(out), "--force", "--head", "nape"]) == 2
    assert "--head: ['nape'] are not hinge joints of the model" in capsys.readouterr().err
    gripper = write_urdf(tmp_path / "g", Options(arm_dof=3, gripper=True))
    args = ["--arm", "left=left_gripper", "--arm", "right=right_gripper"]  # joints, but on no arm's chain
    assert main(["robots", "import", str(gripper), "--out", str(out), "--force", *args]) == 2
    assert "left arm (given): joints ['left_gripper'] lie on no chain to a hand" in capsys.readouterr().err


def test_millimetre_meshes_and_a_pedestal(tmp_path):
    """Hands drawn in millimetres are scaled by 0.001; a humanoid fixed to a `world` link on a pedestal, its feet
    off the floor, keeps its height, maps both arms and the head, and holds the legs (by their names)."""
    desc = write_urdf(tmp_path, Options(arm_dof=3, hand_mesh="stl"))
    import trimesh

    mesh = desc.parent.parent / "meshes" / "hand.stl"
    big = trimesh.load(str(mesh))
    big.apply_scale(1000.0)
    big.export(str(mesh))
    text = desc.read_text()
    text = text.replace('<link name="pelvis">', '<link name="world"/><link name="pedestal"><visual><geometry><box '
                        'size="0.2 0.2 0.6"/></geometry></visual></link><joint name="stand" type="fixed"><parent '
                        'link="world"/><child link="pedestal"/><origin xyz="0 0 0.3"/></joint><joint name="seat" '
                        'type="fixed"><parent link="pedestal"/><child link="pelvis"/><origin xyz="0 0 0.35"/></joint>'
                        '<link name="pelvis">')  # fmt: skip
    desc.write_text(text)
    res = import_description(desc, tmp_path / "robots" / "p.yaml")
    assert any("in millimetres: scaled by 0.001" in g for g in res.guesses)
    parts = _parts(res)
    assert parts["left arm"][0] == "left_shoulder_pitch" and parts["right arm"][0] == "right_shoulder_pitch"
    assert parts["head"] == ["neck_yaw", "neck_pitch"] and parts["left leg"] == [f"left_{j}" for j in LEG]
    m, _ = _home(load_robot_config(res.yaml_path))
    hand = m.mesh(0)
    assert np.ptp(m.mesh_vert[hand.vertadr[0] : hand.vertadr[0] + hand.vertnum[0]], axis=0).max() < 0.1


def test_forward_from_the_feet_when_no_name_says_left_or_right(tmp_path):
    """A Y-forward description whose limbs are named a_/b_ (no left/right): it faces where its feet point, and
    the arm on its left after the turn is the left arm."""
    desc = write_urdf(tmp_path, Options(forward="y", arm_dof=3))
    desc.write_text(desc.read_text().replace("left_", "a_").replace("right_", "b_"))
    res = import_description(desc, tmp_path / "robots" / "f.yaml")
    assert any("faces +y: where the feet point" in g for g in res.guesses)
    parts = _parts(res)
    assert parts["left arm"][0] == "a_shoulder_pitch" and parts["right arm"][0] == "b_shoulder_pitch"
    m, d = _home(load_robot_config(res.yaml_path))
    assert d.site_xpos[m.site("l_shoulder_site").id][1] > 0.1


def test_an_imported_humanoid_is_filmed_facing_it_with_its_upper_body_in_frame(messy):
    """The import writes no camera of its own (one framed the whole robot, legs and pedestal, from the side): its
    videos and renders go through the framing camera, which faces the robot and frames its upper body."""
    from robogest.backends.mujoco_sim import load_sim_model
    from robogest.backends.render import framing_camera, make_renderer, render_frame, video_camera
    from robogest.errors import MissingDependencyError

    robot = load_robot_config(messy.yaml_path)
    sim = load_sim_model(robot)
    m, d = sim.model, mujoco.MjData(sim.model)
    assert m.ncam == 0
    d.qpos[sim.qpos_idx] = robot.rest_q_rad
    mujoco.mj_forward(m, d)
    cam = video_camera(m, d, robot, 160, 120)
    assert isinstance(cam, mujoco.MjvCamera) and cam.azimuth == framing_camera(m, d, robot, 160, 120).azimuth
    try:
        renderer = make_renderer(m, 160, 120)
    except MissingDependencyError as e:
        pytest.skip(f"no offscreen GL here: {e}")
    try:
        renderer.enable_segmentation_rendering()
        seg = render_frame(renderer, d, cam)
    finally:
        renderer.close()
    geom = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
    body = np.where(geom >= 0, m.geom_bodyid[np.maximum(geom, 0)], -1)
    sites = {s for v in robot.retarget for s in v.robot}
    for name in sites:  # every retargeting site's body (head, shoulders, elbows, hands) is seen
        assert (body == m.site_bodyid[m.site(name).id]).any(), f"{name}'s body is not in the frame"
