"""A dynamic scene's animation: shaded frames, labelled, as a looping GIF.

Beyond the paper (its sequences are shown as videos): each frame carries its
label (the variant, the frame name and its place in the sequence), so a
reader of the report knows which reconstruction and which frame is shown.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import cv2
import numpy as np

__all__ = ["label_frame", "write_animation"]


def label_frame(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of ``image`` (H, W, 3) uint8 with ``text`` in its top-left corner.

    Dark text on a light box, sized to the image (font scale 1 per 640 pixels
    of width, at least 0.35), so it reads at any resolution.
    """
    out = np.ascontiguousarray(image).copy()
    h, w = out.shape[:2]
    scale = max(0.35, w / 640.0)
    thick = max(1, round(scale))
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    pad = max(2, round(4 * scale))
    x1, y1 = min(w, tw + 2 * pad), min(h, th + base + 2 * pad)
    out[:y1, :x1] = (255 - (255 - out[:y1, :x1].astype(np.int16)) // 4).astype(np.uint8)
    cv2.putText(
        out,
        text,
        (pad, pad + th),
        cv2.FONT_HERSHEY_SIMPLEX,
        scale,
        (20, 20, 20),
        thick,
        cv2.LINE_AA,
    )
    return out


def write_animation(
    images: Iterable[np.ndarray],
    path: str | Path,
    fps: float = 8,
    labels: Sequence[str] | None = None,
) -> Path:
    """An animated GIF (looping) of a dynamic scene's frames.

    Parameters
    ----------
    images : iterable of ndarray of uint8, shape (H, W, 3)
        The frames, all the same shape; a generator is consumed one frame at
        a time.
    path : str or Path
        GIF file to write (atomically).
    fps : float
        Frames per second.
    labels : sequence of str, optional
        One label per frame, drawn in its corner (:func:`label_frame`).

    Notes
    -----
    Pillow merges consecutive identical frames into one longer frame, so the
    GIF can hold fewer frames than ``images`` (its timing stays right).

    Memory: each frame is kept only as the palette image the GIF stores (one
    byte a pixel, Pillow's own adaptive conversion, so the file is the same as
    converting at save), never as a list of RGB arrays, which would hold three
    bytes a pixel of every frame at once.
    """
    from PIL import Image

    from colourhs.common.files import atomic_output

    frames, shape = [], None
    for i, im in enumerate(images):
        f = np.asarray(im)
        if shape is None:
            shape = f.shape
            if len(shape) != 3 or shape[2] != 3:
                raise ValueError(f"write_animation: frames must be (H, W, 3), got {shape}")
        if f.shape != shape:
            raise ValueError(f"write_animation: frame {i} has shape {f.shape}, frame 0 {shape}")
        if f.dtype != np.uint8:
            raise ValueError(f"write_animation: frame {i} is {f.dtype}, expected uint8")
        if labels is not None:
            if i >= len(labels):
                raise ValueError(f"write_animation: {len(labels)} labels for more frames")
            f = label_frame(f, labels[i])
        frames.append(Image.fromarray(f, mode="RGB").convert("P", palette=Image.Palette.ADAPTIVE))
    if not frames:
        raise ValueError("write_animation: no frames")
    if labels is not None and len(labels) != len(frames):
        raise ValueError(f"write_animation: {len(labels)} labels for {len(frames)} frames")
    path = Path(path)
    with atomic_output(path) as tmp:
        frames[0].save(
            tmp,
            format="GIF",
            save_all=True,
            append_images=frames[1:],
            duration=max(1, round(1000.0 / fps)),
            loop=0,
        )
    return path
