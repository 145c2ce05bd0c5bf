"""The README's DDP recipe, ``torchrun --standalone --nproc_per_node 2 ... robogest train``, on CPU (gloo)."""

from __future__ import annotations

import json
import os
import signal
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

    # last.pt every epoch; best.pt once an epoch may be it (not Gesticulator's pre-training epoch)
    assert ranks[0]["saved"][0] == "last.pt" and ranks[0]["saved"].count("last.pt") == 2
    assert "best.pt" in ranks[0]["saved"]
    assert ranks[1]["saved"] == []
    assert sorted(ranks[0]["computed"]) == ["take_000", "take_001", "take_002"] and ranks[1]["computed"] == []
    assert sorted(p.name for p in out.iterdir()) == ["best.pt", "history.json", "last.pt"]  # window files removed
    assert r.stdout.count("best checkpoint:") == 1


#: The reduced Rhythmic Gesticulator (conftest.RHYTHMIC_SMALL's structure, narrower still) on windows of 4 blocks.
RHYTHMIC = {
    "hidden": 32, "audio_channels": 16, "audio_layers": 2, "vq_channels": 16, "lexicon_size": 8, "lexeme_dim": 16,
    "motion_feat_dim": 16, "audio_feat_dim": 16, "style_dim": 4, "pe_dim": 4, "latent_groups": 4,
    "latent_classes": 8, "window_blocks": 4,
}  # fmt: skip


def _torchrun(args: list[str], probe: Path, cwd: Path, timeout_s: float) -> subprocess.CompletedProcess:
    """``torchrun --nproc_per_node 2 ddp_probe.py ARGS``; on ``timeout_s`` the whole process group is killed (the
    ranks too, not only the launcher) and the test fails as a hang."""
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
           str(Path(__file__).with_name("ddp_probe.py")), *args]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PROBE_OUT": str(probe), "OMP_NUM_THREADS": "1"}
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=cwd,
                         start_new_session=True)  # fmt: skip
    try:
        out, err = p.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
        pytest.fail(f"2-rank torchrun still running after {timeout_s} s (hung):\n{out[-2000:]}\n{err[-2000:]}")
    return subprocess.CompletedProcess(cmd, p.returncode, out, err)


@pytest.fixture(scope="module")
def few_words(tmp_path_factory) -> Path:
    """Two takes, only the first transcribed: with one window per rank per step, some steps give one rank word
    frames and the other none."""
    root = make_fixture_dataset(tmp_path_factory.mktemp("ddp") / "few_words", n_takes=2, duration_s=8.0, seed=2)
    (root / "take_001.json").unlink()  # a take without a transcript: no word frames
    return root


@pytest.mark.slow
def test_rhythmic_ranks_keep_identical_state_through_every_stage_and_a_rank_without_words_does_not_hang(
    few_words, tmp_path
):
    """One epoch per stage (encoder, lexicon, generator, interpreters) on 2 ranks: after each, both ranks hold the
    same weights and buffers (codebook, its usage, the silent-lexeme counts), although the codebook is restarted
    from data and the ranks see different data; and audio-encoder steps where one rank's window has word frames
    and the other's has none finish (that rank's loss used to have no graph, so it skipped the gradient
    all-reduce and the other rank waited for ever). The takes' time-scaled audio blocks are made once, one take by
    each rank, and kept in the cache folder."""
    out, probe = tmp_path / "out", tmp_path / "probe"
    probe.mkdir()
    sets = [a for k, v in RHYTHMIC.items() for a in ("--set", f"{k}={v}")]
    r = _torchrun(
        ["train", "--model", "rhythmic", "--data", str(few_words), "--out", str(out), "--epochs", "4",
         "--batch-size", "2", "--device", "cpu", "--text-encoder", "hash-test", "--cache-dir", str(tmp_path / "c"),
         "--window-stride", "10", "--val-fraction", "0", "--dist-timeout-s", "120", *sets],
        probe, tmp_path, timeout_s=400,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    ranks = [json.loads((probe / f"rank{k}.json").read_text()) for k in (0, 1)]
    words = [rk["words"] for rk in ranks]
    assert len(words[0]) == len(words[1]) == len(ranks[0]["epochs"][0]["batches"])  # every encoder step, both
    assert any(a != b for a, b in zip(*words, strict=True)), words  # the fixture did split words from no words

    assert len(ranks[0]["state"]) == len(ranks[1]["state"]) == 4
    for stage, s0, s1 in zip(
        ("encoder", "lexicon", "generator", "interpreters"), *(rk["state"] for rk in ranks), strict=True
    ):
        assert s0.keys() == s1.keys()
        differ = {k: (s0[k], s1[k]) for k in s0 if s0[k] != pytest.approx(s1[k], rel=1e-6, abs=1e-9)}
        assert not differ, (stage, differ)
    first, last = ranks[0]["state"][0], ranks[0]["state"][-1]
    assert first["vq.codebook"] != last["vq.codebook"] and last["lex_total"] > 0  # they did change
    assert len(list((tmp_path / "c" / "rhythmic-blocks").iterdir())) == 2  # blocks kept for the next run...
    assert len(ranks[0]["tsm"]) == len(ranks[1]["tsm"]) == 1  # ...each take's made once, the ranks sharing the work
