"""Model options: `robogest train --set KEY=VALUE` -> config fields, checked by name and type."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

from robogest.cli.main import main
from robogest.cli.train_cmds import parse_options
from robogest.errors import InputError
from robogest.learn import config_with_overrides


@dataclass(frozen=True)
class Demo:
    n: int = 3
    rate: float = 0.5
    name: str = "a"
    flag: bool = True
    sizes: tuple = (1, 2)


def test_overrides_are_typed_like_the_defaults():
    c = config_with_overrides(Demo, "demo", {"rate": 1, "sizes": [4, 5], "flag": False}, n=7)
    assert c == Demo(n=7, rate=1.0, name="a", flag=False, sizes=(4, 5)) and isinstance(c.rate, float)
    with pytest.raises(InputError, match=r"demo option n=2\.5: expected int \(default 3\)"):
        config_with_overrides(Demo, "demo", {"n": 2.5})
    with pytest.raises(InputError, match="demo option flag=1: expected bool"):
        config_with_overrides(Demo, "demo", {"flag": 1})
    with pytest.raises(InputError, match="demo option n=True: expected int"):
        config_with_overrides(Demo, "demo", {"n": True})
    with pytest.raises(InputError, match=r"unknown demo option\(s\): size; options are flag, n, name, rate, sizes"):
        config_with_overrides(Demo, "demo", {"size": 1})


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"past": -5}, r"gesticulator option past=-5: expected a finite number >= 0"),
        ({"dropout": float("nan")}, r"gesticulator option dropout=nan: expected a finite number"),
        ({"dropout": 2.0}, r"gesticulator option dropout=2\.0: a dropout probability is below 1"),
        ({"past": 2}, r"gesticulator options: past=2 must be at least n_prev_poses=3"),
        ({"train_frames": 0}, r"gesticulator options: train_frames=0 must be at least 1"),
    ],
)
def test_values_a_model_cannot_train_with_are_refused_before_training(overrides, message):
    """They were tracebacks from torch, one of them after 7 epochs of training (past=2 broke the autoregressive
    input only when it was switched on)."""
    from robogest.generators.learned.gesticulator.model import GesticulatorConfig

    with pytest.raises(InputError, match=message):
        config_with_overrides(GesticulatorConfig, "gesticulator", overrides)
    with pytest.raises(InputError, match=r"s2ag option lr_generator=0: a learning rate is above 0"):
        from robogest.generators.learned.s2ag.config import S2AGConfig

        config_with_overrides(S2AGConfig, "s2ag", {"lr_generator": 0})


def test_set_values_are_json_or_plain_words():
    assert parse_options(["a=3", "b=0.5", "c=true", "d=[1, 2]", "e=joint", "f="]) == {
        "a": 3, "b": 0.5, "c": True, "d": [1, 2], "e": "joint", "f": ""
    }  # fmt: skip
    with pytest.raises(InputError, match="--set 'lexicon': expected KEY=VALUE"):
        parse_options(["lexicon"])


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--set", "lexicon_size=big"], "rhythmic option lexicon_size='big': expected int"),
        (["--set", "nope=1"], r"unknown rhythmic option\(s\): nope"),
        (["--epochs", "2"], r"needs --epochs >= 4 \(got 2\)"),
    ],
)
def test_train_cli_refuses_bad_options_in_one_line(tmp_path, capsys, argv, message):
    """Checked before any training, exit code 2, nothing written."""
    pytest.importorskip("torch")
    from robogest.data import make_fixture_dataset

    data = make_fixture_dataset(tmp_path / "d", n_takes=1, duration_s=3.0)
    out = tmp_path / "out"
    rc = main(["train", "--model", "rhythmic", "--data", str(data), "--out", str(out), "--text-encoder", "hash-test",
               "--cache-dir", str(tmp_path / "c"), "--epochs", "4", *argv])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert re.search(message, err[0]), err[0]
    assert not out.exists() or not any(out.iterdir())
