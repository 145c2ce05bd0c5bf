"""Gesticulator inference: a checkpoint -> motion for a whole speech or frame by frame (streaming)."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator

import numpy as np

from robogest.data.features import expmap_to_motion, speech_inputs
from robogest.generators.learned.checkpoint import CheckpointGenerator
from robogest.generators.learned.gesticulator.model import GesticulatorConfig, GesticulatorNet, torch
from robogest.motion.human_motion import HumanMotion
from robogest.speech.types import Speech


class GesticulatorGenerator(CheckpointGenerator):
    """Generator backed by a checkpoint from ``robogest train --model gesticulator``.

    Parameters
    ----------
    checkpoint : path-like
        ``.pt`` file; it carries the model, feature and normalisation settings.
    device : str
        Torch device for inference (``"cpu"`` by default: the model is small and CPU is fast enough).
    encoder : TextEncoder, optional
        Overrides the text encoder the checkpoint names (must have the same dimension).
    """

    name = "gesticulator"
    config_cls = GesticulatorConfig
    net_cls = GesticulatorNet

    def inputs(self, speech: Speech) -> np.ndarray:
        """Normalised model inputs ``(T, n_input)`` of ``speech`` (re-analysed when its fps differs)."""
        acoustic, text = speech_inputs(self.at_model_rate(speech), self.features, self.encoder)  # (T, 69), (T, D)
        return np.concatenate([self.norm.acoustic(acoustic), text], axis=1)  # (T, 69 + D)

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Denormalised exponential maps ``(T, n_pose)`` for normalised inputs ``x`` ``(T, n_input)``.

        The first frame is repeated ``past`` times before and the last ``future`` times after, so every frame
        has a full window; the autoregression starts from the mean pose.
        """
        c = self.config
        if x.shape[0] == 0:
            return np.zeros((0, c.n_pose), np.float32)
        padded = np.concatenate([np.repeat(x[:1], c.past, 0), x, np.repeat(x[-1:], c.future, 0)])  # (T + 30, F)
        with torch.inference_mode():
            s = torch.from_numpy(padded.astype(np.float32)).to(self.device)[None]  # (1, T + 30, F)
            y = self.model(s, None, period=1)[0]  # (T, P); no ground truth, so its own poses feed back
        return self.norm.pose_inverse(y.cpu().numpy())

    def infer_stream(self, frames: Iterable[np.ndarray]) -> Iterator[np.ndarray]:
        """Frame-by-frame inference with the model's 1 s look-ahead.

        Parameters
        ----------
        frames : iterable of ndarray [shape=(n_input,)]
            Normalised input frames (:meth:`inputs` rows) as they arrive.

        Yields
        ------
        ndarray [shape=(n_pose,)], radians
            Pose of frame ``t``, available once frame ``t + future - 1`` has arrived (end of input flushes the
            rest). Equal to :meth:`predict` on the whole sequence.
        """
        c = self.config
        window: deque = deque(maxlen=c.window)  # encoded frames, (frame_dim,) each
        prev = torch.zeros(1, c.n_prev_poses, c.n_pose, device=self.device)
        last = None
        pending = 0  # frames received but not yet answered

        def emit() -> np.ndarray:
            nonlocal prev
            win = torch.stack(tuple(window))[None].flatten(1)  # (W, frame_dim) -> (1, W * frame_dim)
            y = self.model.decode(self.model.layer1(win), prev)  # (1, P)
            prev = torch.cat([prev[:, 1:], y[:, None]], dim=1)  # (1, 3, P)
            return self.norm.pose_inverse(y[0].cpu().numpy())

        with torch.inference_mode():
            for frame in frames:
                enc = self.model.frame_encoder(torch.as_tensor(np.asarray(frame, np.float32), device=self.device))
                if last is None:
                    window.extend([enc] * c.past)  # left padding: the first frame repeated
                window.append(enc)
                last = enc
                pending += 1
                if len(window) == c.window:
                    pending -= 1
                    yield emit()
            while pending > 0:  # right padding: the last frame repeated
                window.append(last)
                if len(window) == c.window:
                    pending -= 1
                    yield emit()

    def generate(self, speech: Speech, seed: int = 0) -> HumanMotion:
        """Motion at ``speech.fps`` lasting as long as the speech (deterministic: dropout is off)."""
        torch.manual_seed(seed)
        poses = self.predict(self.inputs(speech))  # (T, J * 3) at the model's fps
        return expmap_to_motion(poses, self.features.fps).resample(speech.fps, n_frames=speech.n_frames)
