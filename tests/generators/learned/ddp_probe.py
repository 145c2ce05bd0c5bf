"""``robogest train`` under ``torchrun`` with a record of what each rank did (for test_ddp_torchrun.py).

Run as ``torchrun ... ddp_probe.py train ARGS``: the real CLI runs unchanged; wrappers around the trainer's batch
split, checkpoint writer and evaluation, and around the feature computation, write ``$PROBE_OUT/rank{RANK}.json``:
the window indices of every batch, the checkpoints written, a checksum of the weights each epoch, per-tensor sums of
the whole state (weights and buffers) each epoch, the takes whose features this rank computed and, for the rhythmic
model, whether each contrastive loss (audio-encoder stage) saw any word frame and the takes' audio it time-scaled
(blocks per take).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

from robogest.cli.main import main
from robogest.data import datasets
from robogest.learn import trainer

RANK = int(os.environ["RANK"])
RECORD: dict[str, list] = {
    "epochs": [],
    "saved": [],
    "weights": [],
    "state": [],
    "computed": [],
    "words": [],
    "tsm": [],
}


def _wrap(module, name: str, before) -> None:
    original = getattr(module, name)

    def wrapper(*args, **kwargs):
        result = original(*args, **kwargs)
        before(result, *args)
        return result

    setattr(module, name, wrapper)


_wrap(trainer, "_batches", lambda out, n, *_: RECORD["epochs"].append({"n": n, "batches": [b.tolist() for b in out]}))
_wrap(trainer, "save_checkpoint", lambda _, ckpt, path: RECORD["saved"].append(Path(path).name))
_wrap(trainer, "_evaluate", lambda _, run, *a: RECORD["weights"].append(
    float(sum(p.detach().double().sum() for p in run.model.parameters()))
))  # fmt: skip
_wrap(trainer, "_evaluate", lambda _, run, *a: RECORD["state"].append(
    {k: float(v.detach().double().sum()) for k, v in run.model.state_dict().items()}
))  # fmt: skip
_wrap(datasets, "compute_take", lambda _, files, *a: RECORD["computed"].append(files.name))

try:
    from robogest.generators.learned.rhythmic import cache as rhythmic_cache
    from robogest.generators.learned.rhythmic import model as rhythmic_model
except ImportError:  # no torch: nothing trains anyway
    pass
else:
    _wrap(rhythmic_cache, "tsm_mel_blocks", lambda out, *a: RECORD["tsm"].append(out.shape[0]))
    _wrap(rhythmic_model.RhythmicNet, "contrastive_loss", lambda _, net, text, layers, mask: RECORD["words"].append(
        bool(mask.any())
    ))  # fmt: skip

if __name__ == "__main__":
    try:
        rc = main(sys.argv[1:])
    finally:
        Path(os.environ["PROBE_OUT"], f"rank{RANK}.json").write_text(json.dumps(RECORD))
    sys.exit(rc)
