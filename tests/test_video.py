"""Episodes as videos (vdtn_marl/io/video.py): GIF and MP4 files written atomically with
imageio, opened again here and their frames counted."""

from __future__ import annotations

import numpy as np
import pytest

from vdtn_marl.errors import ConfigError
from vdtn_marl.io import video as video_module
from vdtn_marl.io.video import MP4_BLOCK, VIDEO_FORMATS, check_video, write_video


def _frames(count: int, height: int = 45, width: int = 80) -> list[np.ndarray]:
    """``count`` frames of one flat colour each: red rises frame by frame."""
    colours = [(40 * i % 256, 80, 160) for i in range(count)]
    return [np.full((height, width, 3), c, dtype=np.uint8) for c in colours]


def test_a_gif_holds_every_frame_in_order_and_loops(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    frames = _frames(6)
    path = write_video(tmp_path, frames, fps=20.0, video_format="gif")
    assert path == tmp_path / "episode.gif"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episode.gif"]  # no temp file left
    read = iio.imread(path, index=None)
    assert read.shape[:3] == (6, 45, 80)
    np.testing.assert_array_equal(read[..., :3], np.stack(frames))  # flat colours: lossless
    meta = iio.immeta(path, index=0)
    assert meta["duration"] == pytest.approx(50.0) and meta["loop"] == 0  # 1/20 s, forever


def test_an_mp4_holds_every_frame_padded_to_whole_blocks(tmp_path):
    iio = pytest.importorskip("imageio.v3")
    pytest.importorskip("imageio_ffmpeg")
    path = write_video(tmp_path, _frames(7), fps=20.0, video_format="mp4")
    read = np.stack(list(iio.imiter(path, plugin="FFMPEG")))
    assert read.shape[0] == 7
    assert read.shape[1] % MP4_BLOCK == 0 and read.shape[2] % MP4_BLOCK == 0
    assert (read.shape[1], read.shape[2]) == (48, 80)
    # H.264 is lossy: the colours come back close
    assert abs(float(read[3, 10, 10, 0]) - 120.0) < 8.0


@pytest.mark.parametrize("video_format", list(VIDEO_FORMATS))
def test_a_format_without_its_library_names_the_extra(video_format, monkeypatch):
    monkeypatch.setattr(video_module, "installed", lambda module: False)
    with pytest.raises(ConfigError, match=r"video_format.*vdtn-marl\[video\]"):
        check_video(video_format)


def test_an_unknown_format_names_the_key_and_the_choices():
    with pytest.raises(ConfigError, match="video_format='avi'") as err:
        check_video("avi")
    assert all(name in str(err.value) for name in VIDEO_FORMATS)


def test_a_video_needs_frames(tmp_path):
    pytest.importorskip("imageio")
    with pytest.raises(ValueError, match="at least one frame"):
        write_video(tmp_path, [], fps=20.0, video_format="gif")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", [["jocc", "experiment=smoke"], ["bench", "benchmark=smoke"]])
def test_video_without_its_library_is_one_line_before_anything_is_written(
    command, tmp_path, monkeypatch, capsys
):
    from vdtn_marl import cli

    monkeypatch.setattr(video_module, "installed", lambda module: module != "imageio_ffmpeg")
    monkeypatch.chdir(tmp_path)
    assert cli.main([*command, "video=true", "video_format=mp4"]) == 2
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert line.startswith("error: ") and "video_format=mp4" in line
    assert "pip install 'vdtn-marl[video]'" in line
    assert list(tmp_path.iterdir()) == []
