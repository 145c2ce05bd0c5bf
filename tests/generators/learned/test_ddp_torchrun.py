"""The README's DDP recipe, ``torchrun --standalone --nproc_per_node 2 ... robogest train``, on CPU (gloo)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")
if not torch.distributed.is_available():
    pytest.skip("this PyTorch build has no torch.distributed", allow_module_level=True)

from robogest.data import make_fixture_dataset  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
#: Narrow models (the papers' structure) so two processes train in seconds on two cores.
MODELS = {
    "gesticulator": ["--set", "frame_dim=32", "--set", "hidden=[64,32]", "--set", "cond_dim=32", "--set",
                     "pretrain_epochs=1"],
    "s2ag": ["--set", "d_gen=32", "--set", "d_disc=32", "--set", "gru_layers=1", "--set", "val_windows=2"],
}  # fmt: skip


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return make_fixture_dataset(tmp_path_factory.mktemp("ddp") / "ds", n_takes=3, duration_s=6.0, seed=1)


@pytest.mark.slow
@pytest.mark.parametrize("model", sorted(MODELS))
def test_two_ranks_train_disjoint_shards_and_rank_0_alone_writes(dataset, tmp_path, model):
    """Gesticulator goes through the DistributedDataParallel wrapper, S2AG (its own GAN step) through per-parameter
    all-reduce hooks; either way both ranks train every epoch on disjoint halves of each batch, end with the same
    weights, and only rank 0 computes features and writes checkpoints."""
    out, probe = tmp_path / "out", tmp_path / "probe"
    probe.mkdir()
    cmd = [
        sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
        str(Path(__file__).with_name("ddp_probe.py")), "train", "--model", model, "--data", str(dataset),
        "--out", str(out), "--epochs", "2", "--batch-size", "8", "--device", "cpu", "--text-encoder", "hash-test",
        "--cache-dir", str(tmp_path / "cache"), "--window-stride", "10", "--val-fraction", "0.34", *MODELS[model],
    ]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PROBE_OUT": str(probe), "OMP_NUM_THREADS": "1"}
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=240, cwd=tmp_path)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    ranks = [json.loads((probe / f"rank{k}.json").read_text()) for k in (0, 1)]

    assert len(ranks[0]["epochs"]) == len(ranks[1]["epochs"]) == 2
    for e0, e1 in zip(ranks[0]["epochs"], ranks[1]["epochs"], strict=True):
        a, b = ([i for batch in e["batches"] for i in batch] for e in (e0, e1))
        assert a and b and not set(a) & set(b)  # both trained, on different windows
        assert sorted(a + b) == list(range(e0["n"]))  # together every window once
        assert len(e0["batches"]) == len(e1["batches"]) >= 2  # same number of steps (DDP needs it)
    assert ranks[0]["weights"] == pytest.approx(ranks[1]["weights"], rel=1e-6)  # replicas stay identical
    assert ranks[0]["weights"][0] != ranks[0]["weights"][1]  # ...and they trained

    assert ranks[0]["saved"][:2] == ["last.pt", "best.pt"] and ranks[0]["saved"].count("last.pt") == 2
    assert ranks[1]["saved"] == []
    assert sorted(ranks[0]["computed"]) == ["take_000", "take_001", "take_002"] and ranks[1]["computed"] == []
    assert sorted(p.name for p in out.iterdir()) == ["best.pt", "history.json", "last.pt"]  # window files removed
    assert r.stdout.count("best checkpoint:") == 1
