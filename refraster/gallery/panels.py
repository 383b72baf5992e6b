"""Labelled panels side by side: the gallery's picture assembly (a leaf of the gallery)."""

from __future__ import annotations

import numpy as np

__all__ = ["label", "side_by_side"]


def label(image, text):
    """``image`` with a white strip on top carrying ``text`` (PIL's default bitmap font)."""
    from PIL import Image, ImageDraw
    img = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    strip = 14
    h, w = img.shape[:2]
    canvas = Image.new("RGB", (w, h + strip), (255, 255, 255))
    canvas.paste(Image.fromarray((img * 255.0 + 0.5).astype(np.uint8)), (0, strip))
    ImageDraw.Draw(canvas).text((2, 1), text, fill=(0, 0, 0))
    return np.asarray(canvas, np.float32) / 255.0


def side_by_side(images, gap=4):
    """``images`` left to right, bottom-padded with white, ``gap`` white columns apart."""
    h = max(im.shape[0] for im in images)
    parts = []
    for k, im in enumerate(images):
        if k:
            parts.append(np.ones((h, gap, 3), np.float32))
        pad = np.ones((h - im.shape[0],) + im.shape[1:], np.float32)
        parts.append(np.concatenate([np.asarray(im, np.float32), pad], axis=0))
    return np.concatenate(parts, axis=1)
