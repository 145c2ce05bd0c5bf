"""A 2-rank CPU ``torchrun`` of each learned model on a crop of the real BEAT2 sample take (../shared/data; skipped
without it): every run finishes, and both ranks end every epoch with the same weights and buffers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
if not torch.distributed.is_available():
    pytest.skip("this PyTorch build has no torch.distributed", allow_module_level=True)

from tests.conftest import SHARED_DATA  # noqa: E402
from tests.generators.learned.test_ddp_torchrun import MODELS, RHYTHMIC, _torchrun  # noqa: E402

CROP_S = 16.0
ARGS = {**MODELS, "rhythmic": [a for k, v in RHYTHMIC.items() for a in ("--set", f"{k}={v}")]}
EPOCHS = {"gesticulator": 2, "s2ag": 2, "rhythmic": 4}


@pytest.fixture(scope="module")
def beat2_crop(tmp_path_factory) -> Path:
    """The first ``CROP_S`` s of the BEAT2 take: audio, SMPL-X motion and its words, as a plain-pairs folder."""
    import soundfile as sf

    from robogest.speech.transcript import read_transcript

    src, name = SHARED_DATA / "beat2", "2_scott_0_1_1"
    if not (src / f"{name}.wav").is_file():
        pytest.skip(f"shared data not found at {src}")
    root = tmp_path_factory.mktemp("beat2") / "crop"
    root.mkdir()
    audio, sr = sf.read(src / f"{name}.wav", dtype="float32")
    sf.write(root / f"{name}.wav", audio[: round(CROP_S * sr)], sr, subtype="FLOAT")
    with np.load(src / f"{name}.npz") as z:
        n = round(CROP_S * int(z["mocap_frame_rate"]))
        np.savez(root / f"{name}.npz", **{k: (z[k][:n] if k in ("poses", "trans", "expressions") else z[k]) for k in z})
    words = [w for w in read_transcript(src / f"{name}.TextGrid").words if w.end_s <= CROP_S]
    doc = {"words": [{"word": w.text, "start": w.start_s, "end": w.end_s} for w in words]}
    (root / f"{name}.json").write_text(json.dumps(doc), encoding="utf-8")
    return root


@pytest.mark.slow
@pytest.mark.shared
@pytest.mark.parametrize("model", sorted(ARGS))
def test_two_ranks_on_a_real_take_end_with_identical_weights(beat2_crop, tmp_path_factory, tmp_path, model):
    cache = tmp_path_factory.getbasetemp() / "beat2-cache"  # features once for the three models
    probe = tmp_path / "probe"
    probe.mkdir()
    r = _torchrun(
        ["train", "--model", model, "--data", str(beat2_crop), "--out", str(tmp_path / "out"),
         "--epochs", str(EPOCHS[model]), "--batch-size", "8", "--device", "cpu", "--text-encoder", "hash-test",
         "--cache-dir", str(cache), "--window-stride", "10", "--val-fraction", "0", "--dist-timeout-s", "300",
         *ARGS[model]],
        probe, tmp_path, timeout_s=400,
    )  # fmt: skip
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    s0, s1 = (json.loads((probe / f"rank{k}.json").read_text())["state"] for k in (0, 1))
    assert len(s0) == len(s1) == EPOCHS[model]
    for epoch, (a, b) in enumerate(zip(s0, s1, strict=True), 1):
        differ = {k: (a[k], b[k]) for k in a if a[k] != pytest.approx(b[k], rel=1e-6, abs=1e-9)}
        assert a.keys() == b.keys() and not differ, (epoch, differ)
    assert s0[0] != s0[-1]  # they trained
