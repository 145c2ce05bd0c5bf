from __future__ import annotations

import errno
import os
import stat

import numpy as np
import pytest

from robogest.errors import InputError, RobogestError
from robogest.fileio import atomic_path, check_output_path, publish, read_npz, read_text_capped


def test_atomic_path_publishes_with_ordinary_permissions(tmp_path):
    out = tmp_path / "sub" / "a.txt"
    old = os.umask(0o022)
    try:
        with atomic_path(out) as tmp:
            tmp.write_text("hello")
            assert not out.exists()  # nothing visible until the block succeeds
    finally:
        os.umask(old)
    assert out.read_text() == "hello"
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert [p.name for p in out.parent.iterdir()] == ["a.txt"]


def test_atomic_path_leaves_nothing_on_error(tmp_path):
    out = tmp_path / "a.npz"
    out.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(out, ".npz") as tmp:
        tmp.write_text("half")
        raise RuntimeError("crash mid-write")
    assert out.read_text() == "old"  # the previous file is untouched
    assert [p.name for p in tmp_path.iterdir()] == ["a.npz"]


def test_atomic_path_never_replaces_a_device_fifo_or_folder(tmp_path):
    fifo = tmp_path / "p"
    os.mkfifo(fifo)
    (tmp_path / "to_fifo").symlink_to(fifo)
    (tmp_path / "d").mkdir()
    cases = [(fifo, "FIFO"), (tmp_path / "to_fifo", "via the symlink"), (tmp_path / "d", "is a folder")]
    null = tmp_path / "null"  # a stand-in for /dev/null: the real one is never risked
    try:
        os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        cases.append((null, "device"))
    except PermissionError:
        pass  # not root: the FIFO covers special files
    for target, why in cases:
        with pytest.raises(InputError, match=why), atomic_path(target):
            pytest.fail("the block must not run")
    assert stat.S_ISFIFO(fifo.stat().st_mode) and (tmp_path / "to_fifo").is_symlink()
    assert not null.exists() or stat.S_ISCHR(null.stat().st_mode)


def test_atomic_path_writes_through_a_symlink(tmp_path):
    (tmp_path / "real.txt").write_text("old")
    (tmp_path / "link.txt").symlink_to("real.txt")
    with atomic_path(tmp_path / "link.txt") as tmp:
        tmp.write_text("new")
    assert (tmp_path / "link.txt").is_symlink() and (tmp_path / "real.txt").read_text() == "new"


def test_atomic_path_write_error_is_one_line_and_leaves_nothing(tmp_path):
    out = tmp_path / "a.bin"
    msg = r"a\.bin: cannot write \(No space left on device\); nothing was written"
    with pytest.raises(RobogestError, match=msg), atomic_path(out) as tmp:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert list(tmp_path.iterdir()) == []


def test_atomic_path_on_a_full_disk(full_disk):
    with pytest.raises(RobogestError, match="No space left on device"), atomic_path(full_disk / "x.bin") as tmp:
        tmp.write_bytes(b"\1" * 100_000)
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_check_output_path_parent_is_a_file(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"--out .*f/sub/x\.npz: .*f is a file, not a folder"):
        check_output_path(tmp_path / "f" / "sub" / "x.npz", "--out")
    assert check_output_path(tmp_path / "new" / "sub" / "x.npz") == tmp_path / "new" / "sub" / "x.npz"
    assert not (tmp_path / "new").exists()  # checking creates nothing


def test_read_npz_refuses_pickles_and_caps_sizes(tmp_path):
    np.savez(tmp_path / "obj.npz", a=np.array([{"x": 1}], dtype=object))
    with pytest.raises(InputError, match="pickled Python objects"):
        read_npz(tmp_path / "obj.npz")
    np.savez(tmp_path / "big.npz", a=np.zeros(1000), b=np.zeros(1000))
    with pytest.raises(InputError, match=r"larger than the .* GiB robogest reads"):
        read_npz(tmp_path / "big.npz", max_bytes=12_000)
    got = read_npz(tmp_path / "big.npz", max_bytes=16_000)
    assert sorted(got) == ["a", "b"] and got["a"].shape == (1000,)
    (tmp_path / "text.npz").write_text("not a zip")
    with pytest.raises(InputError, match=r"text\.npz: not a readable \.npz"):
        read_npz(tmp_path / "text.npz")


def test_video_writer_full_disk_is_one_line_and_leaves_nothing(full_disk):
    pytest.importorskip("av")
    from robogest.media.video import VideoWriter

    msg = r"v\.mp4: cannot write \(No space left on device\)"
    with pytest.raises(RobogestError, match=msg), VideoWriter(full_disk / "v.mp4", 64, 64, 25) as w:
        for k in range(50):
            w.add_frame(np.full((64, 64, 3), k * 5, np.uint8))
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_checkpoint_on_a_full_disk(full_disk):
    torch = pytest.importorskip("torch")
    from robogest.learn.checkpoint import save_checkpoint

    with pytest.raises(RobogestError, match=r"c\.pt: cannot write \(No space left on device\)"):
        save_checkpoint({"w": torch.zeros(100_000)}, full_disk / "c.pt")
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_publish_never_replaces_a_fifo(tmp_path):
    fifo = tmp_path / "p"
    os.mkfifo(fifo)
    tmp = tmp_path / "t"
    tmp.write_text("x")
    with pytest.raises(InputError, match="FIFO"):
        publish(tmp, fifo)
    assert stat.S_ISFIFO(fifo.stat().st_mode)


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")  # soundfile's cffi I/O callbacks
def test_exports_and_speech_audio_on_a_full_disk(full_disk):
    """The ROS exports and libsndfile's short write (an AssertionError in soundfile) were tracebacks."""
    pytest.importorskip("rosbags")
    from types import SimpleNamespace

    from robogest.speech.export import write_wav
    from robogest.trajectory.export import export_trajectory
    from tests.trajectory.test_export import _traj

    traj = _traj(n=20_000)
    for name in ("t.mcap", "bag"):
        with pytest.raises(RobogestError, match=rf"{name}: cannot write \(No space left on device\); nothing was"):
            export_trajectory(traj, full_disk / name)
    speech = SimpleNamespace(audio=np.zeros(200_000, np.float32), sr=16000)
    with pytest.raises(RobogestError, match=r"s\.wav: cannot write .*nothing was written"):
        write_wav(speech, full_disk / "s.wav")
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]


def test_an_export_below_a_file_is_refused_before_any_work(tmp_path):
    from robogest.trajectory.export import check_export

    (tmp_path / "a.wav").write_text("x")
    for target in ("a.wav/bag", "a.wav/t.mcap", "a.wav/t.csv"):
        with pytest.raises(InputError, match=r"--export .*a\.wav is a file, not a folder"):
            check_export(tmp_path / target)
    os.symlink(tmp_path / "nowhere", tmp_path / "dangling")
    with pytest.raises(InputError, match=r"--export .*dangling: is a symlink"):
        check_export(tmp_path / "dangling")


def test_read_text_capped_refuses_devices_huge_sparse_and_binary_files(tmp_path):
    p = tmp_path / "a.urdf"
    p.write_text("<robot/>")
    assert read_text_capped(p, what="URDF") == "<robot/>"
    with pytest.raises(InputError, match=r"URDF /dev/zero: not a regular file"):
        read_text_capped("/dev/zero", what="URDF")
    big = tmp_path / "big.urdf"
    with open(big, "wb") as f:
        f.truncate(3 * 1024**3)  # sparse: 3 GB on paper, nothing on disk
    with pytest.raises(InputError, match=r"big.urdf: 3072.0 MiB, larger than the 64 MiB"):
        read_text_capped(big, what="URDF")
    b = tmp_path / "b.urdf"
    b.write_bytes(b"<robot>\xff\xfe")
    with pytest.raises(InputError, match=r"b.urdf: not UTF-8 text \(byte 7\)"):
        read_text_capped(b, what="URDF")
    with pytest.raises(InputError, match=r"missing\.urdf: cannot read"):
        read_text_capped(tmp_path / "missing.urdf", what="URDF")


def test_read_npz_refuses_a_decompression_bomb_but_reads_compressed_data(tmp_path, rng):
    """A 1.5 MB compressed .npz allocated 1.5 GiB: a member may expand at most 100x (recorded numbers: 1-10x)."""
    np.savez_compressed(tmp_path / "bomb.npz", q=np.zeros((2_000_000, 1)))
    with pytest.raises(InputError, match=r"bomb\.npz: array 'q' expands from \d+ to 16000128 bytes"):
        read_npz(tmp_path / "bomb.npz")
    data = np.round(rng.normal(size=(300_000, 4)), 3)  # 9.6 MB of recorded-like numbers
    np.savez_compressed(tmp_path / "real.npz", q=data, small=np.zeros(1000))  # 8 kB of zeros: under 1 MiB
    got = read_npz(tmp_path / "real.npz")
    np.testing.assert_array_equal(got["q"], data)


def test_speech_audio_on_a_full_disk_prints_no_ignored_tracebacks(full_disk, monkeypatch):
    """Written through a Python file object, libsndfile's I/O callbacks failed on a full disk, and Python printed
    each failure as an "Exception ignored ... Traceback" block on stderr above the one error line."""
    import sys
    from types import SimpleNamespace

    from robogest.speech.export import write_wav

    ignored = []
    monkeypatch.setattr(sys, "unraisablehook", ignored.append)
    speech = SimpleNamespace(audio=np.zeros(200_000, np.float32), sr=16000)
    with pytest.raises(RobogestError, match=r"s\.wav: cannot write \(libsndfile could not write it; the disk may"):
        write_wav(speech, full_disk / "s.wav")
    assert ignored == []
    assert sorted(p.name for p in full_disk.iterdir()) == ["filler"]
