"""`robogest train` then `robogest speak --generator gesticulator --checkpoint` in the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from robogest.cli.main import main
from robogest.trajectory import Trajectory

pytest.importorskip("torch")


@pytest.mark.parametrize("model", ["gesticulator", "s2ag", "rhythmic"])
def test_train_then_speak_with_checkpoint(model, tmp_path, capsys):
    from robogest.data import make_fixture_dataset

    make_fixture_dataset(tmp_path / "data", n_takes=3, duration_s=6.0)
    epochs = "4" if model == "rhythmic" else "1"  # the rhythmic model's four stages train one after another
    argv = ["train", "--model", model, "--data", str(tmp_path / "data"), "--out", str(tmp_path / "ckpt"),
            "--epochs", epochs, "--text-encoder", "hash-test", "--cache-dir", str(tmp_path / "cache")]  # fmt: skip
    if model == "gesticulator":  # one epoch, autoregressive from the start (best.pt is never a pre-training epoch)
        argv += ["--set", "pretrain_epochs=0"]
    assert main(argv) == 0
    ckpt = tmp_path / "ckpt" / "last.pt"
    assert ckpt.is_file()
    out = tmp_path / "t.npz"
    assert main(["speak", "Hello there, you and I. ... Maybe.", "--generator", model, "--checkpoint", str(ckpt),
                 "--save", str(out)]) == 0  # fmt: skip
    traj = Trajectory.load(out)
    assert np.isfinite(traj.q_rad).all()
    assert (traj.q_rad >= traj.q_min_rad - 1e-9).all() and (traj.q_rad <= traj.q_max_rad + 1e-9).all()
    assert f"generator: {model}" in capsys.readouterr().out
    # Audio without a transcript (the learned generators must cope with no words).
    wav = tmp_path / "t.wav"
    assert main(["speak", "--audio", str(wav), "--generator", model, "--checkpoint", str(ckpt)]) == 0


def test_missing_checkpoint_is_one_line(tmp_path, capsys):
    rc = main(["speak", "Hi.", "--generator", "gesticulator", "--checkpoint", str(tmp_path / "nope.pt")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "nope.pt" in err[0]
