"""The six faces of the workpiece, in one fixed order.

The workpiece model (``models/workpiece/workpiece.sdf``) is a 0.15 x 0.10 x
0.05 m box with its frame at the part's centre. Each face carries a coloured
plate (visual ``face_<key>``) and a die-style pattern of dots (visuals
``face_<key>_dot<i>``), so faces can be told apart with or without colour;
opposite faces' dot counts add up to seven.

``FACES`` entries are ``(name, outward unit normal in the workpiece frame,
colour name)``; the inspection task counts a face as seen from its normal.
"""

from __future__ import annotations

FACES: tuple[tuple[str, tuple[int, int, int], str], ...] = (
    ("+x", (1, 0, 0), "red"),
    ("-x", (-1, 0, 0), "cyan"),
    ("+y", (0, 1, 0), "green"),
    ("-y", (0, -1, 0), "magenta"),
    ("+z", (0, 0, 1), "blue"),
    ("-z", (0, 0, -1), "yellow"),
)

# Box size along the workpiece frame's x, y, z (metres).
WORKPIECE_SIZE = (0.15, 0.10, 0.05)

# Dots on each face (a die: opposite faces add up to 7).
FACE_DOTS = {"+x": 1, "-x": 6, "+y": 2, "-y": 5, "+z": 3, "-z": 4}

# Plate colour of each colour name, RGBA in [0, 1].
COLOUR_RGBA = {
    "red": (0.90, 0.10, 0.10, 1.0),
    "cyan": (0.10, 0.85, 0.90, 1.0),
    "green": (0.10, 0.75, 0.15, 1.0),
    "magenta": (0.85, 0.15, 0.80, 1.0),
    "blue": (0.15, 0.35, 1.00, 1.0),
    "yellow": (0.95, 0.85, 0.10, 1.0),
}


def face_key(name: str) -> str:
    """SDF-safe key of a face name: ``"+x"`` -> ``"px"``, ``"-z"`` -> ``"nz"``."""
    return ("p" if name[0] == "+" else "n") + name[1]


def face_visual_name(name: str) -> str:
    """Name of the coloured plate visual of a face in ``workpiece.sdf``."""
    return f"face_{face_key(name)}"
