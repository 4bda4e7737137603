"""Videos: a folder of frames -> mp4 (Udacity's video.py), and frames appended one at a time."""

from __future__ import annotations

from pathlib import Path

import cv2
import imageio_ffmpeg
import numpy as np
import pytest

from clonedrive.evaluate.video import (
    VideoWriter,
    default_video_path,
    encode_folder,
    frames_to_video,
)


def decode_video(path: Path) -> tuple[dict, list[np.ndarray]]:
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    width, height = meta["size"]
    frames = [np.frombuffer(raw, np.uint8).reshape(height, width, 3) for raw in reader]
    return meta, frames


def colour_frame(index: int, width: int = 320, height: int = 160) -> np.ndarray:
    """Frame ``index``: a flat colour that changes with the index (RGB)."""
    frame = np.zeros((height, width, 3), dtype=np.uint8)
    frame[:] = (25 * index, 255 - 25 * index, 128)
    return frame


def write_folder(folder: Path, count: int) -> None:
    folder.mkdir()
    for index in range(count):
        name = f"2026_01_02_03_04_05_{index * 67:03d}.jpg"
        bgr = cv2.cvtColor(colour_frame(index), cv2.COLOR_RGB2BGR)
        assert cv2.imwrite(str(folder / name), bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])


def test_folder_to_video(tmp_path: Path) -> None:
    folder = tmp_path / "run1"
    write_folder(folder, 10)
    path = frames_to_video(folder, fps=60)
    assert path == tmp_path / "run1.mp4" and path.is_file()
    meta, frames = decode_video(path)
    assert meta["size"] == (320, 160)
    assert meta["fps"] == pytest.approx(60.0)
    assert meta["codec"].startswith("h264") and "yuv420p" in meta["pix_fmt"]
    assert len(frames) == 10
    for index, frame in enumerate(frames):  # in name order, colours kept (RGB, not BGR)
        assert np.abs(frame[40:120, 80:240].astype(int) - colour_frame(index)[0, 0]).max() < 12
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_bad_frames_are_skipped_and_counted(tmp_path: Path) -> None:
    folder = tmp_path / "frames"
    write_folder(folder, 3)
    (folder / "2026_01_02_03_04_05_001.jpg").write_bytes(b"not a jpeg")
    small = np.zeros((80, 160, 3), dtype=np.uint8)
    assert cv2.imwrite(str(folder / "2026_01_02_03_04_05_002.jpg"), small)
    (folder / "notes.txt").write_text("not a frame")
    summary = encode_folder(folder, fps=15, out=tmp_path / "out" / "video.mp4")
    assert summary.path == tmp_path / "out" / "video.mp4"
    assert summary.frames == 3
    assert [name for name, _ in summary.skipped] == [
        "2026_01_02_03_04_05_001.jpg",
        "2026_01_02_03_04_05_002.jpg",
    ]
    assert "160x80" in summary.skipped[1][1]
    assert len(decode_video(summary.path)[1]) == 3


def test_empty_or_missing_folder(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nowhere"):
        frames_to_video(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no frames"):
        frames_to_video(tmp_path / "empty")
    assert not (tmp_path / "empty.mp4").exists()


def test_default_path_is_beside_the_folder(tmp_path: Path) -> None:
    assert default_video_path(str(tmp_path / "run1") + "/") == tmp_path / "run1.mp4"


def test_video_writer_appends_frames(tmp_path: Path) -> None:
    path = tmp_path / "eval" / "lap.mp4"
    with VideoWriter(path, fps=15) as writer:
        for index in range(5):
            writer.append(colour_frame(index, 64, 48))
        with pytest.raises(ValueError, match="32x48"):
            writer.append(np.zeros((48, 32, 3), dtype=np.uint8))
        with pytest.raises(ValueError, match="uint8"):
            writer.append(np.zeros((48, 64, 3), dtype=np.float32))
        assert not path.exists()  # only complete files appear
    assert writer.frames_written == 5
    meta, frames = decode_video(path)
    assert meta["size"] == (64, 48) and len(frames) == 5
    # Even sizes are piped to ffmpeg as YUV 4:2:0: colours come back as they went in (RGB).
    for index, frame in enumerate(frames):
        assert np.abs(frame[8:40, 8:56].astype(int) - colour_frame(index)[0, 0]).max() < 12


def test_video_writer_odd_size_and_abort(tmp_path: Path) -> None:
    path = tmp_path / "odd.mp4"
    with VideoWriter(path, fps=10) as writer:
        for index in range(3):
            writer.append(colour_frame(index, 33, 21))
    meta, frames = decode_video(path)
    assert meta["size"] == (34, 22) and len(frames) == 3
    for index, frame in enumerate(frames):  # piped as RGB, scaled by ffmpeg
        assert np.abs(frame[6:16, 6:28].astype(int) - colour_frame(index)[0, 0]).max() < 12
    aborted = tmp_path / "aborted.mp4"
    with pytest.raises(RuntimeError), VideoWriter(aborted) as writer:
        writer.append(colour_frame(0))
        raise RuntimeError("evaluation failed")
    assert list(tmp_path.glob("*aborted*")) == []
    # Closing without frames (e.g. in a finally block after a failure) writes nothing.
    assert VideoWriter(tmp_path / "none.mp4").close() is None
    assert not (tmp_path / "none.mp4").exists()


def test_video_writer_composes_callables_off_the_loop_and_reports_their_errors(tmp_path):
    path = tmp_path / "composed.mp4"
    with VideoWriter(path, fps=10) as writer:
        for index in range(4):
            writer.append(lambda index=index: colour_frame(index, 64, 48))
    meta, frames = decode_video(path)
    assert meta["size"] == (64, 48) and len(frames) == 4
    failing = VideoWriter(tmp_path / "failing.mp4", fps=10)
    failing.append(lambda: colour_frame(0, 64, 48))
    failing.append(lambda: np.zeros((10, 10), dtype=np.uint8))  # not RGB: fails on the thread
    with pytest.raises(ValueError, match="uint8 RGB"):
        failing.close()
    assert not (tmp_path / "failing.mp4").exists()
    assert list(tmp_path.glob(".failing*")) == []
