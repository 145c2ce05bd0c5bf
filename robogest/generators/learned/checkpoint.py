"""What every checkpoint-backed generator shares: loading, in-memory wrapping, text encoder, frame rate.

Importing this module needs PyTorch (``pip install 'robogest[learn]'``).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np

from robogest.data.features import FeatureConfig, text_encoder_for
from robogest.data.prep import Normalization
from robogest.errors import InputError
from robogest.generators.base import Generator
from robogest.learn import require_torch
from robogest.learn.checkpoint import build_model, load_checkpoint, normalization_arrays
from robogest.speech.types import Speech

if TYPE_CHECKING:
    from robogest.text import TextEncoder

_G = TypeVar("_G", bound="CheckpointGenerator")


class CheckpointGenerator(Generator):
    """A generator whose network, feature settings and normalisation all come from one ``.pt`` file.

    Subclasses set ``name`` (the model name the checkpoint must carry), ``config_cls`` (with
    ``from_dict``) and ``net_cls`` (a ``torch.nn.Module`` built from that config).

    Parameters
    ----------
    checkpoint : path-like
        ``.pt`` file from ``robogest train --model NAME``.
    device : str
        Torch device for inference (CPU is fast enough for these small models).
    encoder : TextEncoder, optional
        Overrides the text encoder the checkpoint names (must have the same dimension).
    """

    # Any: each model family has its own config dataclass and network, which its subclass uses by their fields.
    config_cls: ClassVar[Any]
    net_cls: ClassVar[Any]

    def __init__(
        self,
        checkpoint: str | os.PathLike | None = None,
        device: str = "cpu",
        encoder: TextEncoder | None = None,
        **options: Any,
    ) -> None:
        require_torch(f"the {self.name!r} generator")
        if checkpoint is None:
            raise InputError(
                f"the {self.name} generator needs --checkpoint FILE.pt; train one with "
                f"`robogest train --model {self.name} --data DIR --out DIR`"
            )
        ckpt = load_checkpoint(checkpoint, map_location=device)
        if ckpt["model_name"] != self.name:
            raise InputError(f"{checkpoint}: a {ckpt['model_name']!r} checkpoint, not a {self.name} one")
        try:  # a file from another robogest version, or edited: one line naming the file and the part
            config = self.config_cls.from_dict(ckpt["model_config"])
        except (TypeError, ValueError, KeyError, AttributeError) as e:
            raise InputError(f"{checkpoint}: invalid model config ({type(e).__name__}: {e})") from None
        model = build_model(ckpt, lambda: self.net_cls(config), checkpoint, device)  # weights against the config
        try:
            what = "feature config"
            features = FeatureConfig.from_dict(ckpt["feature_config"])
            what = "normalisation"
            norm = Normalization.from_dict(normalization_arrays(ckpt))
        except (TypeError, ValueError, KeyError, AttributeError) as e:
            raise InputError(f"{checkpoint}: invalid {what} ({type(e).__name__}: {e})") from None
        n_pose = getattr(config, "n_pose", None)  # S2AG works in its own pose space
        sizes = {"pose_mean": n_pose, "pose_std": n_pose} if n_pose is not None else {}
        bad = [k for k, n in sizes.items() if np.shape(getattr(norm, k)) != (n,)]
        if bad:
            raise InputError(f"{checkpoint}: invalid normalisation ({bad[0]} is not {sizes[bad[0]]} values)")
        self.path: Path | None = Path(checkpoint)
        self._adopt(model, features, norm, encoder, options)

    @classmethod
    def from_model(
        cls: type[_G],
        model: Any,
        features: FeatureConfig,
        norm: Normalization | None = None,
        encoder: TextEncoder | None = None,
        **options: Any,
    ) -> _G:
        """Wrap an in-memory model (tests, notebooks) without a checkpoint file."""
        self = cls.__new__(cls)
        self.path = None
        self._adopt(model, features, norm, encoder, options)
        return self

    def _adopt(
        self,
        model: Any,
        features: FeatureConfig,
        norm: Normalization | None,
        encoder: TextEncoder | None,
        options: dict[str, Any],
    ) -> None:
        self.config, self.features, self._norm = model.config, features, norm
        self.device = next(model.parameters()).device
        self.model = model.eval()
        self._encoder = encoder
        self.configure(**options)

    def configure(self, **options: Any) -> None:
        """Run-time options beyond the checkpoint (e.g. S2AG's speaker); this base generator takes none.

        Raises
        ------
        InputError
            An option the generator does not know.
        """
        if options:
            raise InputError(f"the {self.name} generator has no option(s) {', '.join(sorted(options))}")

    @property
    def norm(self) -> Normalization:
        """The training data's statistics (a model wrapped by :meth:`from_model` without ``norm`` has none)."""
        if self._norm is None:
            raise InputError(
                f"{self.path or 'the model'}: no normalisation statistics; "
                f"pass norm= to {type(self).__name__}.from_model"
            )
        return self._norm

    @property
    def encoder(self) -> TextEncoder:
        if self._encoder is None:
            self._encoder = text_encoder_for(self.features)
        if self._encoder.dim != self.config.n_text:
            raise InputError(
                f"{self.path or 'the model'}: its text encoder gives {self._encoder.dim}-d vectors, the model needs "
                f"{self.config.n_text}; the checkpoint's feature config does not match its model"
            )
        return self._encoder

    def at_model_rate(self, speech: Speech) -> Speech:
        """``speech`` re-analysed at the frame rate the model was trained at, if it differs."""
        if abs(speech.fps - self.features.fps) <= 1e-6:
            return speech
        from robogest.speech import analyze

        return analyze(speech.audio, speech.sr, speech.words, self.features.speech_config(), source=speech.source)
