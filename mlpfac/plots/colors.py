"""One colour per controller, the same in every plot and in the viewer's comparisons."""

from __future__ import annotations

import zlib
from collections.abc import Iterable

RGB = tuple[int, int, int]

KNOWN: dict[str, RGB] = {
    "adaptive": (31, 119, 180),  # blue: the paper's scheme
    "corradini": (255, 127, 14),  # orange
    "kanayama": (44, 160, 44),  # green
    "oracle": (60, 60, 60),  # near black: the true functions
    "adaptive-ukf": (148, 103, 189),
    "adaptive-cautious": (140, 86, 75),
    "adaptive-forget": (227, 119, 194),
    "adaptive-q": (188, 189, 34),
    "adaptive-prior": (23, 190, 207),
    "adaptive-gains": (214, 39, 40),
    "adaptive-best": (0, 0, 128),
}
NAMES: dict[RGB, str] = dict(
    zip(
        KNOWN.values(),
        ["blue", "orange", "green", "black", "purple", "brown", "pink", "olive", "cyan", "red", "navy"],
        strict=True,
    )
)
PALETTE: tuple[RGB, ...] = (  # for controllers not named above, picked by name
    (214, 39, 40), (148, 103, 189), (140, 86, 75), (227, 119, 194), (188, 189, 34), (23, 190, 207),
    (127, 127, 127), (174, 199, 232), (255, 187, 120), (152, 223, 138), (255, 152, 150), (197, 176, 213),
)  # fmt: skip
NAMES |= dict(zip(PALETTE, ["red", "purple", "brown", "pink", "olive", "cyan", "grey", "light blue",
                            "light orange", "light green", "light red", "lavender"], strict=True))  # fmt: skip


def controller_colors(names: Iterable[str]) -> dict[str, RGB]:
    """A colour per name: the known ones first, then each other name one the set does not use yet
    (starting from a place its name picks, so a name keeps its colour from plot to plot)."""
    names = list(dict.fromkeys(names))
    out = {n: KNOWN[n] for n in names if n in KNOWN}
    for n in names:
        if n not in out:
            start = zlib.crc32(n.encode())
            free = [c for i in range(len(PALETTE)) if (c := PALETTE[(start + i) % len(PALETTE)]) not in out.values()]
            out[n] = free[0] if free else PALETTE[start % len(PALETTE)]
    return out


def mpl(rgb: RGB) -> tuple[float, float, float]:
    """An RGB colour as matplotlib takes it."""
    return (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255)
