"""Episodes as videos: RGB frames (``render_mode="rgb_array"``, :mod:`vdtn_marl.envs.render`)
written as a GIF or an MP4 with imageio, an optional dependency (``pip install
'vdtn-marl[video]'``, which brings imageio and its FFmpeg binary).

imageio writes GIFs through Pillow, which matplotlib already installs, and MP4s (H.264)
through ``imageio-ffmpeg``'s own FFmpeg; TorchRL's ``VideoRecorder`` writes through a logger's
``log_video``, whose MP4 writer needs torchcodec and which writes no GIF.
The file is encoded in memory and written atomically (:func:`~.files.atomic_write_bytes`).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from pathlib import Path

from vdtn_marl.errors import ConfigError
from vdtn_marl.io.files import atomic_write_bytes

#: ``video_format`` choices: the modules each needs (all in the ``video`` extra).
VIDEO_FORMATS = {"gif": ("imageio",), "mp4": ("imageio", "imageio_ffmpeg")}
VIDEO_STEM = "episode"  # <run>/episode.gif or .mp4
#: ``video_scenarios`` choices: the held-out scenarios an evaluation with ``video=true`` draws,
#: as the stems of their files (vdtn_marl/experiment/evaluate.py draws them).
VIDEO_SCENARIOS = {
    "first": (VIDEO_STEM,),  # the first scenario, drawn during the evaluation
    "best_worst": ("episode_best", "episode_worst"),  # highest and lowest control return
}
#: H.264 players want frame sides divisible by 16: frames are padded (edge pixels) to it.
MP4_BLOCK = 16


def installed(module: str) -> bool:
    """Whether ``module`` can be imported (found without importing it)."""
    return importlib.util.find_spec(module) is not None


def check_video(video_format: str, key: str = "video_format") -> str:
    """``video_format`` if it is a format of :data:`VIDEO_FORMATS` whose modules are installed,
    else :class:`ConfigError` naming ``key`` (or the extra to install)."""
    if video_format not in VIDEO_FORMATS:
        raise ConfigError(
            f"{key}={video_format!r} is not allowed; choose one of {', '.join(VIDEO_FORMATS)}"
        )
    missing = [m for m in VIDEO_FORMATS[video_format] if not installed(m)]
    if missing:
        raise ConfigError(
            f"video=true ({key}={video_format}) needs {missing[0]}, which is not installed; "
            "pip install 'vdtn-marl[video]'"
        )
    return video_format


def encode_video(frames: Sequence, fps: float, video_format: str = "gif") -> bytes:
    """``frames`` (uint8 [H, W, 3] each, all of one size) as the bytes of a GIF that loops or
    of an H.264 MP4, ``fps`` frames per second."""
    import imageio.v3 as iio
    import numpy as np

    check_video(video_format)
    if not len(frames):
        raise ValueError("a video needs at least one frame")
    stack = np.stack([np.asarray(f, dtype=np.uint8) for f in frames])
    if video_format == "gif":
        duration_ms = 1000.0 / fps
        return iio.imwrite("<bytes>", stack, extension=".gif", duration=duration_ms, loop=0)
    pad_h, pad_w = (-stack.shape[1]) % MP4_BLOCK, (-stack.shape[2]) % MP4_BLOCK
    stack = np.pad(stack, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)), mode="edge")
    return iio.imwrite("<bytes>", stack, extension=".mp4", plugin="FFMPEG", fps=fps)


def write_video(
    folder: str | Path, frames: Sequence, fps: float, video_format: str, stem: str = VIDEO_STEM
) -> Path:
    """``<folder>/<stem>.<format>`` from ``frames`` (:func:`encode_video`), atomically."""
    path = Path(folder) / f"{stem}.{video_format}"
    return atomic_write_bytes(path, encode_video(frames, fps, video_format))
