"""Issue 36: an import reads and copies only files inside the description's own tree (or a --search-path), gives
its copies the user's umask and never broader permissions than their source, and leaves nothing when it fails,
full disk included; unreadable descriptions are one line."""

from __future__ import annotations

import os
import stat

import pytest

from robogest.cli.main import main
from robogest.errors import InputError, RobogestError
from robogest.tools.importer import import_description
from tests.robots.test_urdf_import import arm_urdf

pytest.importorskip("trimesh")


def _tree(tmp_path, mesh_ref: str):
    """``tmp_path/ws/toy_description/urdf/arm.urdf`` whose hand is ``mesh_ref``; returns (urdf, out yaml)."""
    pkg = tmp_path / "ws" / "toy_description"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "meshes").mkdir()
    urdf = pkg / "urdf" / "arm.urdf"
    urdf.write_text(arm_urdf(f'<mesh filename="{mesh_ref}"/>'))
    return urdf, tmp_path / "out" / "robots" / "arm.yaml"


def _stl(path):
    from tests.robots.humanoids import write_mesh

    write_mesh(path, "stl")


def _nothing_left(tmp_path):
    assert not (tmp_path / "out").exists(), sorted(str(p) for p in (tmp_path / "out").rglob("*"))


@pytest.mark.parametrize(
    "ref",
    ["package://../../secret.stl", "file://{tmp}/secret.stl", "{tmp}/secret.stl", "../../../secret.stl"],
    ids=["package-dotdot", "file-url", "absolute", "relative-dotdot"],
)
def test_meshes_outside_the_tree_are_refused(tmp_path, ref):
    _stl(tmp_path / "secret.stl")
    urdf, out = _tree(tmp_path, ref.format(tmp=tmp_path))
    with pytest.raises(InputError, match=r"secret\.stl|not a package name"):
        import_description(urdf, out)
    _nothing_left(tmp_path)


def test_a_symlink_out_of_the_tree_is_refused_and_search_path_allows(tmp_path):
    _stl(tmp_path / "secret.stl")
    urdf, out = _tree(tmp_path, "package://toy_description/meshes/hand.stl")
    (urdf.parent.parent / "meshes" / "hand.stl").symlink_to(tmp_path / "secret.stl")
    with pytest.raises(InputError, match=r"outside the description's folders .* --search-path"):
        import_description(urdf, out)
    _nothing_left(tmp_path)
    res = import_description(urdf, out, search_paths=[tmp_path])  # named by the user: allowed
    assert len(list((res.mjcf_path.parent / "assets").iterdir())) == 1


def test_copies_are_never_broader_than_their_source(tmp_path):
    urdf, out = _tree(tmp_path, "package://toy_description/meshes/hand.stl")
    mesh = urdf.parent.parent / "meshes" / "hand.stl"
    _stl(mesh)
    os.chmod(mesh, 0o600)  # a private file stays private
    old = os.umask(0o022)
    try:
        res = import_description(urdf, out)
    finally:
        os.umask(old)
    (copy,) = (res.mjcf_path.parent / "assets").iterdir()
    assert stat.S_IMODE(copy.stat().st_mode) == 0o600
    assert stat.S_IMODE(res.yaml_path.stat().st_mode) == 0o644  # 0666 minus the umask


def test_xacro_include_outside_the_tree_is_refused(tmp_path):
    pytest.importorskip("xacro")
    (tmp_path / "evil.xacro").write_text('<robot xmlns:xacro="http://www.ros.org/wiki/xacro"/>')
    pkg = tmp_path / "ws" / "pkg"
    (pkg / "urdf").mkdir(parents=True)
    x = pkg / "urdf" / "r.urdf.xacro"
    x.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                 f'<xacro:include filename="{tmp_path}/evil.xacro"/></robot>')  # fmt: skip
    with pytest.raises(InputError, match=r"xacro include .*evil\.xacro lies outside"):
        import_description(x, tmp_path / "out" / "r.yaml")
    _nothing_left(tmp_path)


@pytest.mark.parametrize("kind", ["binary", "dev-zero", "sparse"])
def test_unreadable_descriptions_are_one_line(tmp_path, kind, capsys):
    if kind == "binary":
        path = tmp_path / "x.urdf"
        path.write_bytes(bytes(range(256)) * 4)
    elif kind == "dev-zero":
        path = "/dev/zero"
    else:
        path = tmp_path / "big.urdf"
        with open(path, "wb") as f:
            f.truncate(3 * 1024**3)  # sparse: no disk used
    assert main(["robots", "import", str(path), "--out", str(tmp_path / "out" / "x.yaml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err
    _nothing_left(tmp_path)


def test_full_disk_leaves_nothing(tmp_path, full_disk, capsys):
    urdf, _ = _tree(tmp_path, "package://toy_description/meshes/hand.stl")
    _stl(urdf.parent.parent / "meshes" / "hand.stl")
    out = full_disk / "robots" / "arm.yaml"
    before = sorted(p.name for p in full_disk.iterdir())
    with pytest.raises(RobogestError, match=r"cannot write \(No space left on device\)"):
        import_description(urdf, out)
    assert sorted(p.name for p in full_disk.iterdir()) == before


def test_package_without_a_name_is_the_descriptions_own(tmp_path):
    """CAD exporters write ``package:///meshes/x.stl``: the description's own package, not a refusal."""
    urdf, out = _tree(tmp_path, "package:///meshes/hand.stl")
    _stl(urdf.parent.parent / "meshes" / "hand.stl")
    res = import_description(urdf, out)
    assert len(list((res.mjcf_path.parent / "assets").iterdir())) == 1


def test_a_description_in_a_home_folder_reads_nothing_above_it(tmp_path, monkeypatch):
    """~/robot.urdf may read ~/meshes, never a neighbour's home (the folder above the file's is /home)."""
    home, other = tmp_path / "home" / "me", tmp_path / "home" / "you"
    (home / "meshes").mkdir(parents=True)
    other.mkdir()
    monkeypatch.setenv("HOME", str(home))
    _stl(home / "meshes" / "hand.stl")
    _stl(other / "secret.stl")
    urdf = home / "robot.urdf"
    urdf.write_text(arm_urdf('<mesh filename="meshes/hand.stl"/>'))
    assert import_description(urdf, tmp_path / "out" / "ok.yaml").yaml_path.is_file()
    urdf.write_text(arm_urdf('<mesh filename="../you/secret.stl"/>'))
    with pytest.raises(InputError, match=r"secret\.stl lies outside"):
        import_description(urdf, tmp_path / "out2" / "no.yaml")
    assert not (tmp_path / "out2").exists()
