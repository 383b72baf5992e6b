"""The README's picture: four gallery pictures, one per paper, each filling its tile.

``python docs/scripts/readme_picture.py GALLERY_DIR docs/img/readme.png``

Tiles (2 × 2, 360 × 270 each): the crank cut by a ragged 2.5D clip surface with hatched caps
(Trapp & Döllner, Fig. 1/10), the crank in Gooch shading with enhanced edges (Nienhaus &
Döllner, Fig. 7), the hull cut away to show its cannons (Burns & Finkelstein, Fig. 1), and the
4D strips with depth-dependent halos (Wang et al., Fig. 1(c)). Each picture is scaled to fit its
tile (Lanczos; a display picture, the gallery's reference renderings are unchanged) on the
picture's own background.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from PIL import Image

TILE = (360, 270)


def _fit(img, background):
    img = img.convert("RGB")
    scale = min(TILE[0] / img.width, TILE[1] / img.height)
    img = img.resize((max(1, round(img.width * scale)), max(1, round(img.height * scale))),
                     Image.LANCZOS)
    tile = Image.new("RGB", TILE, background)
    tile.paste(img, ((TILE[0] - img.width) // 2, (TILE[1] - img.height) // 2))
    return tile


def _panel(img, k, n, gap):
    """Panel ``k`` of ``n`` side by side, separated by ``gap`` columns."""
    w = (img.width - (n - 1) * gap) // n
    x = k * (w + gap)
    return img.crop((x, 0, x + w, img.height))


def _crop_to_content(img, background, margin=6):
    a = np.asarray(img.convert("RGB")).astype(int)
    ys, xs = np.nonzero(np.abs(a - np.array(background)).sum(axis=2) > 24)
    if ys.size == 0:
        return img
    return img.crop((max(xs.min() - margin, 0), max(ys.min() - margin, 0),
                     min(xs.max() + margin + 1, img.width), min(ys.max() + margin + 1, img.height)))


def main(gallery, out):
    g = Path(gallery)
    white, black = (255, 255, 255), (0, 0, 0)
    galleon = Image.open(g / "cutaway_galleon.png")
    halos = _panel(Image.open(g / "halos4d_fig1bc.png"), 1, 3, 8)
    tiles = [
        _fit(_crop_to_content(Image.open(g / "clipsurface_crank_hatched.png"), white), white),
        _fit(_crop_to_content(Image.open(g / "edges" / "edges_crank_gooch.png"), white), white),
        _fit(_crop_to_content(_panel(galleon, 1, 3, 4), white), white),
        _fit(_crop_to_content(halos, black), black),
    ]
    sheet = Image.new("RGB", (2 * TILE[0], 2 * TILE[1]), white)
    for k, tile in enumerate(tiles):
        sheet.paste(tile, ((k % 2) * TILE[0], (k // 2) * TILE[1]))
    sheet.save(out, optimize=True)


if __name__ == "__main__":
    main(*sys.argv[1:3])
