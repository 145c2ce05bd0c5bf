"""`robogest robots import-urdf`: a URDF arm becomes a robot that validates, speaks in the sim and renders lit."""

from __future__ import annotations

import re
import struct

import mujoco
import numpy as np
import pytest
import yaml

from robogest.cli.main import main
from robogest.errors import InputError
from robogest.robot.config import load_robot_config
from robogest.tools.importer import import_description as import_urdf
from robogest.tools.validate import validate
from robogest.trajectory import Trajectory

INERTIAL = (
    '<inertial><origin xyz="0 0 {z}"/><mass value="{m}"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" '
    'ixz="0" iyz="0"/></inertial>'
)


def _link(name: str, length: float, mass: float, shape: str = "cylinder", collide: bool = False) -> str:
    """A link along +Z (or -Z for a negative ``length``: a hanging arm)."""
    geo = (
        f'<cylinder radius="0.016" length="{abs(length)}"/>'
        if shape == "cylinder"
        else f'<box size="0.03 0.03 {abs(length)}"/>'
        if shape == "box"
        else shape
    )
    body = f'<origin xyz="0 0 {length / 2}"/><geometry>{geo}</geometry>'
    col = f"<collision>{body}</collision>" if collide else ""
    return f'<link name="{name}">{INERTIAL.format(z=length / 2, m=mass)}<visual>{body}</visual>{col}</link>'


def _joint(name, parent, child, z, axis, kind="revolute", lo=-1.6, hi=1.6, effort=2.9):
    lim = f'<limit lower="{lo}" upper="{hi}" effort="{effort}" velocity="4.7"/>' if kind != "continuous" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="0 0 {z}"/><axis xyz="{axis}"/>{lim}</joint>'
    )


def arm_urdf(hand_geometry: str = "box") -> str:
    """A 6-joint desk arm with names that say nothing (joint1..), a continuous wrist roll and a prismatic finger."""
    links = [
        '<link name="base_link"><inertial><mass value="0.4"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" '
        'ixz="0" iyz="0"/></inertial><visual><origin xyz="0 0 0.02"/><geometry><box size="0.1 0.1 0.04"/></geometry>'
        '</visual><collision><origin xyz="0 0 0.02"/><geometry><box size="0.1 0.1 0.04"/></geometry></collision>'
        "</link>",
        _link("link1", 0.04, 0.1),
        _link("link2", 0.12, 0.12),
        _link("link3", 0.1, 0.1),
        _link("link4", 0.04, 0.05, "box"),
        _link("link5", 0.06, 0.04, hand_geometry),
        _link("finger", 0.03, 0.01, "box"),
    ]
    joints = [
        _joint("joint1", "base_link", "link1", 0.04, "0 0 1", lo=-2.0, hi=2.0),
        _joint("joint2", "link1", "link2", 0.05, "0 1 0"),
        _joint("joint3", "link2", "link3", 0.12, "0 1 0", lo=-0.2, hi=2.5),
        _joint("joint4", "link3", "link4", 0.1, "0 1 0", lo=-1.7, hi=1.7, effort=1.5),
        _joint("joint5", "link4", "link5", 0.04, "0 0 1", kind="continuous"),
        _joint("finger_slide", "link5", "finger", 0.03, "1 0 0", kind="prismatic", lo=0, hi=0.02),
    ]
    return f'<?xml version="1.0"?>\n<robot name="toy_arm">{"".join(links)}{"".join(joints)}</robot>\n'


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    d = tmp_path_factory.mktemp("urdf")
    (d / "arm.urdf").write_text(arm_urdf())
    return import_urdf(d / "arm.urdf", d / "robots" / "toy.yaml")


def test_import_writes_a_valid_robot(imported):
    assert imported.mjcf_path == imported.yaml_path.parent.parent / "sim" / "toy" / "toy.xml"
    assert [str(p) for p in validate(imported.yaml_path)] == []
    robot = load_robot_config(imported.yaml_path)
    assert robot.joint_names == ["joint1", "joint2", "joint3", "joint4", "joint5"]  # the prismatic finger is welded
    np.testing.assert_allclose(robot.q_max_rad, [2.0, 1.6, 2.5, 1.7, np.pi], atol=1e-5)  # MJCF: 6 digits
    np.testing.assert_allclose(robot.v_max_rad_s, [0.65 * 4.7] * 4 + [0.65 * 4.72], atol=0.006)  # no <limit>: STS3215
    # chain order: joint1 turns about the vertical (the base), so the shoulder is joint2
    assert [v.robot for v in robot.retarget] == [
        ("shoulder_site", "elbow_site"),
        ("elbow_site", "wrist_site"),
        ("wrist_site", "hand_site"),
    ]
    assert robot.retarget[0].human == ("r_shoulder", "r_elbow")
    assert robot.retarget_frame_rpy_rad[0] == pytest.approx(np.pi), "an arm standing up: human directions flipped"
    m = mujoco.MjModel.from_xml_path(str(robot.model_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    site = {m.site(i).name: d.site_xpos[i] for i in range(m.nsite)}
    np.testing.assert_allclose(site["shoulder_site"], [0, 0, 0.09], atol=1e-9)  # on joint2's axis
    np.testing.assert_allclose(site["elbow_site"], [0, 0, 0.21], atol=1e-9)
    np.testing.assert_allclose(site["wrist_site"], [0, 0, 0.31], atol=1e-9)
    assert site["hand_site"][2] == pytest.approx(0.35 + 0.06, abs=0.01), "the end of the last link"
    # position servos sized from <limit effort>: force clipped at the effort, kp = effort / 0.1 rad
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, "joint4")
    assert m.actuator_forcerange[a, 1] == pytest.approx(1.5) and m.actuator_gainprm[a, 0] == pytest.approx(15)
    # a lit floor, and no camera of its own: videos go through the framing camera (tests/sim/test_framing.py)
    assert m.ncam == 0 and m.nlight >= 1 and any(m.geom(g).name == "floor" for g in range(m.ngeom))
    text = imported.yaml_path.read_text()
    assert "welded" in text and "continuous joint 'joint5'" in text and "mapped to the human RIGHT arm" in text


def test_imported_robot_speaks_in_the_sim(imported, tmp_path, capsys):
    out = tmp_path / "hello.npz"
    assert main(["speak", "Hello! Nice to meet you.", "--robot", str(imported.yaml_path), "--save", str(out)]) == 0
    traj = Trajectory.load(out)
    assert traj.q_rad.shape[1] == 5 and np.ptp(traj.q_rad, axis=0).max() > 0.2  # it gestures
    assert "sim tracking error" in capsys.readouterr().out


def test_render_is_lit(imported, tmp_path):
    from robogest.backends.render import render_png
    from robogest.errors import MissingDependencyError

    try:
        png = render_png(load_robot_config(imported.yaml_path), None, tmp_path / "r.png", width=160, height=120)
    except MissingDependencyError:
        pytest.skip("no offscreen OpenGL here")
    from matplotlib import image as mpimg

    rgb = mpimg.imread(png)[..., :3] * 255.0
    assert rgb.mean() > 40 and rgb.std() > 10, "not black, not blank"


def test_cli_import_then_validate(tmp_path, capsys):
    (tmp_path / "arm.urdf").write_text(arm_urdf())
    out = tmp_path / "mine" / "arm.yaml"
    assert main(["robots", "import-urdf", str(tmp_path / "arm.urdf"), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "guessed" in text and f"{out}: valid" in text
    assert (tmp_path / "mine" / "arm" / "scene.xml").is_file()  # no robots/ folder: the model goes beside the YAML
    assert main(["robots", "import-urdf", str(tmp_path / "arm.urdf"), "--out", str(out)]) == 2
    assert "exists; choose another --out or pass --force" in capsys.readouterr().err
    assert main(["robots", "import-urdf", str(tmp_path / "arm.urdf"), "--out", str(out), "--force"]) == 0


def _binary_stl(path, size=0.02):
    """A closed tetrahedron as binary STL (what MuJoCo reads)."""
    v = np.array([[0, 0, 0], [size, 0, 0], [0, size, 0], [0, 0, size]], dtype=np.float32)
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = b"\0" * 80 + struct.pack("<I", len(faces))
    for f in faces:
        data += struct.pack("<12fH", 0, 0, 0, *v[list(f)].ravel(), 0)
    path.write_bytes(data)


def test_package_meshes_are_found_and_copied(tmp_path):
    pkg = tmp_path / "toy_description"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    _binary_stl(pkg / "meshes" / "hand.stl")
    urdf = pkg / "urdf" / "arm.urdf"
    urdf.write_text(arm_urdf('<mesh filename="package://toy_description/meshes/hand.stl"/>'))
    res = import_urdf(urdf, tmp_path / "robots" / "toy.yaml")
    copied = list((res.mjcf_path.parent / "assets").glob("*hand.stl"))
    assert len(copied) == 1 and 'meshdir="assets"' in res.mjcf_path.read_text()
    assert mujoco.MjModel.from_xml_path(str(res.scene_path)).nmesh == 1


def test_two_arms_from_left_right_names(tmp_path):
    """A torso with two hanging 2-joint arms (elbows bending forward) named left_*/right_*: both arms mapped."""

    def side(s, y):
        return _joint(f"{s}_shoulder", "torso", f"{s}_upper", 0.3, "0 1 0").replace(
            'xyz="0 0 0.3"', f'xyz="0 {y} 0.3"'
        ) + _joint(f"{s}_elbow", f"{s}_upper", f"{s}_fore", -0.12, "0 -1 0", lo=0, hi=2.4)

    links = ['<link name="torso"><visual><geometry><box size="0.1 0.16 0.3"/></geometry></visual></link>']
    for s in ("left", "right"):
        links += [_link(f"{s}_upper", -0.12, 0.1), _link(f"{s}_fore", -0.1, 0.1)]
    urdf = tmp_path / "bot.urdf"
    urdf.write_text(f'<robot name="bot">{"".join(links)}{side("left", 0.12)}{side("right", -0.12)}</robot>')
    res = import_urdf(urdf, tmp_path / "bot.yaml")
    raw = yaml.safe_load(res.yaml_path.read_text())
    pairs = {(tuple(v["human"]), tuple(v["robot"])) for v in raw["retarget"]}
    assert (("l_shoulder", "l_elbow"), ("l_shoulder_site", "l_elbow_site")) in pairs
    assert (("r_shoulder", "r_elbow"), ("r_shoulder_site", "r_elbow_site")) in pairs
    assert "retarget_frame_rpy_rad" not in raw, "arms hang at rest: no flip"
    assert [str(p) for p in validate(res.yaml_path)] == []


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("<robot", r"not valid XML"),
        ("<model/>", r"root element is <model>, not <robot>"),
        (arm_urdf('<mesh filename="package://nowhere/hand.stl"/>'), r"mesh 'package://nowhere/hand\.stl' not found"),
        ('<robot name="x"><link name="a"/></robot>', r"no revolute or continuous joints"),
    ],
    ids=["not-xml", "not-urdf", "missing-mesh", "no-joints"],
)
def test_bad_urdf_is_one_clear_error(tmp_path, text, pattern):
    (tmp_path / "x.urdf").write_text(text)
    with pytest.raises(InputError, match=pattern):
        import_urdf(tmp_path / "x.urdf", tmp_path / "x.yaml")


def test_arm_reaching_sideways_is_turned_to_face_forward(tmp_path):
    """An arm lying along +Y at joint zero (its base frame turned 90 deg about Z, the upper arm pitched 90 deg) is
    turned to reach along +X."""
    urdf = arm_urdf()
    for joint, rpy in (("joint1", "0 0 1.5708"), ("joint2", "0 1.5708 0")):
        urdf = re.sub(rf'(<joint name="{joint}".*?<origin xyz="[^"]*")', rf'\1 rpy="{rpy}"', urdf, count=1)
    assert urdf.count("rpy=") == 2
    (tmp_path / "side.urdf").write_text(urdf)
    res = import_urdf(tmp_path / "side.urdf", tmp_path / "side.yaml")
    assert any("to face +X" in g for g in res.guesses)
    robot = load_robot_config(res.yaml_path)
    m = mujoco.MjModel.from_xml_path(str(robot.model_path))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    hand = d.site_xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "hand_site")]
    assert hand[0] > 0.25 and abs(hand[1]) < 1e-6
    assert [str(p) for p in validate(res.yaml_path)] == []


def test_parts_overlapping_at_zero_are_excluded_from_contact(tmp_path):
    """A hand geom long enough to reach back into the forearm (two links up) overlaps at joint zero: excluded."""
    urdf = arm_urdf('<box size="0.03 0.03 0.2"/>')
    urdf = urdf.replace('<origin xyz="0 0 0.03"/><geometry><box size="0.03 0.03 0.2"/>',
                        '<origin xyz="0 0 -0.02"/><geometry><box size="0.03 0.03 0.2"/>')  # fmt: skip
    assert 'xyz="0 0 -0.02"' in urdf
    (tmp_path / "x.urdf").write_text(urdf)
    res = import_urdf(tmp_path / "x.urdf", tmp_path / "x.yaml")
    assert any("excluded" in g for g in res.guesses) and "<exclude" in res.mjcf_path.read_text()
    assert not [str(p) for p in validate(res.yaml_path) if "touches itself" in str(p)]


def test_roles_from_link_names(tmp_path):
    """Joints named j1.. but links named upper_arm, forearm, hand: the sites follow the link names, not the order
    (the chain's order alone would take the base pitch joint j1 for the shoulder)."""
    links = [
        '<link name="base"><visual><geometry><box size="0.08 0.08 0.04"/></geometry></visual></link>',
        _link("tower", 0.06, 0.1), _link("upper_arm", 0.12, 0.1), _link("forearm", 0.1, 0.1), _link("hand", 0.05, 0.05),
    ]  # fmt: skip
    joints = [
        _joint("j1", "base", "tower", 0.02, "0 1 0", lo=-0.5, hi=0.5),
        _joint("j2", "tower", "upper_arm", 0.06, "0 1 0"),
        _joint("j3", "upper_arm", "forearm", 0.12, "0 1 0", lo=-0.2, hi=2.5),
        _joint("j4", "forearm", "hand", 0.1, "0 1 0"),
    ]
    (tmp_path / "r.urdf").write_text(f'<robot name="r">{"".join(links)}{"".join(joints)}</robot>')
    res = import_urdf(tmp_path / "r.urdf", tmp_path / "r.yaml")
    assert any("shoulder at j2" in g and "from the joint and link names" in g for g in res.guesses)
    assert [str(p) for p in validate(res.yaml_path)] == []


def test_an_import_cut_short_while_settling_leaves_nothing(tmp_path, monkeypatch):
    """The start-pose draft is written (in a hidden staging folder) before the rest pose settles; a Ctrl-C (or
    SIGTERM) then leaves nothing: no draft robot, no folder it created, and a file --force would replace intact."""
    import robogest.tools.importer.build as ui

    (tmp_path / "arm.urdf").write_text(arm_urdf())
    out = tmp_path / "robots" / "arm.yaml"

    def interrupted(draft, *a, **k):
        assert draft.is_file() and draft.parent.parent == tmp_path / "sim"  # the draft exists while settling
        raise KeyboardInterrupt

    monkeypatch.setattr(ui, "_settle_rest", interrupted)
    with pytest.raises(KeyboardInterrupt):
        import_urdf(tmp_path / "arm.urdf", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arm.urdf"]
    out.parent.mkdir()
    out.write_text("mine\n")
    with pytest.raises(KeyboardInterrupt):
        import_urdf(tmp_path / "arm.urdf", out, overwrite=True)
    assert out.read_text() == "mine\n" and not (tmp_path / "sim").exists()
