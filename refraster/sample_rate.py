"""How an image-space technique reads a multisampled G-buffer (``docs/multisample.md``,
"Image-space techniques"; ``docs/edges.md``, ``docs/cutaway.md``).

The papers' image-space passes (the edge map's discontinuity filters, the cutaway's jump
flooding) predate multisampling and read one G-buffer value per pixel. At ``samples > 1`` a GPU
port either resolves the G-buffer first and runs the pass once per pixel, or runs the pass on
each sample's G-buffer (each sample index is an image of its own: the pixel lattice moved by
the sample's offset) and resolves the pass's result afterwards. The two are different pictures;
:class:`GBufferSampling` names the choice.
"""

from __future__ import annotations

from dataclasses import dataclass

from ._validate import OptionValue, as_choice
from .multisample import RESOLVE_MODES

__all__ = ["GBufferSampling", "SAMPLING_MODES", "window_shift"]

#: ``"per_sample"``: the pass on each sample's G-buffer, its result resolved afterwards (box
#: filter); ``"resolved"``: the G-buffer resolved first (``GBufferSampling.resolve``), the pass
#: once per pixel.
SAMPLING_MODES = ("per_sample", "resolved")


@dataclass(frozen=True)
class GBufferSampling(OptionValue):
    """Where an image-space technique runs on a multisampled G-buffer.

    Parameters
    ----------
    mode : {"per_sample", "resolved"}
        ``"per_sample"`` (default): the technique's image pass on each sample's G-buffer, its
        output resolved afterwards by the box filter (``VK_RESOLVE_MODE_AVERAGE``);
        ``"resolved"``: the G-buffer resolved first with ``resolve``, the pass once per pixel.
    resolve : {"sample_zero", "average", "min", "max"}
        The Vulkan resolve mode of the G-buffer in the ``"resolved"`` mode (ids always take
        sample 0: no API averages ids). Each technique accepts the modes that mean something
        for its G-buffer (``docs/edges.md``, ``docs/cutaway.md``). Default ``"sample_zero"``,
        the one mode every depth format supports. Not read in the ``"per_sample"`` mode.

    With one sample both modes are the paper's single-sample pass.
    """

    mode: str = "per_sample"
    resolve: str = "sample_zero"

    def __post_init__(self):
        put = object.__setattr__.__get__(self)
        put("mode", as_choice(self.mode, "sampling.mode", SAMPLING_MODES))
        put("resolve", as_choice(self.resolve, "sampling.resolve", RESOLVE_MODES))

    def require_resolve(self, allowed, where):
        """Refuse, with one line, a ``"resolved"`` value whose resolve mode ``where`` has no
        meaning for; returns the value."""
        if self.mode == "resolved" and self.resolve not in allowed:
            raise ValueError(f"sampling.resolve must be one of {', '.join(allowed)} for "
                             f"{where}, got {self.resolve!r}")
        return self


def window_shift(position, width, height):
    """The 4×4 map of OpenGL clip space that moves the window by minus a sample's offset from
    the pixel centre, so that the pixel centres of the moved frame are the sample's positions:
    ``x' = x − (2·o_x/W)·w``, ``y' = y − (2·o_y/H)·w`` with ``o`` in pixels, window y up.
    ``position``: ``(x, y)`` in 1/16 pixel, y down from the pixel's upper-left corner as the
    picture is seen (``docs/multisample.md``, "Positions")."""
    import numpy as np
    ox = (float(position[0]) - 8.0) / 16.0
    oy = (8.0 - float(position[1])) / 16.0
    t = np.eye(4)
    t[0, 3] = -2.0 * ox / width
    t[1, 3] = -2.0 * oy / height
    return t
