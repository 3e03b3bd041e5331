"""Where each of Wang's texture categories sits on the 4 x 4 cloud texture sheet.

Shared by the cloud generator (which picks a category per sprite) and the sheet builder (which
paints each slot in its category's style): 1 flat-bottomed, 3 foggy, 6 puffy, 6 wispy, as in
"Let There Be Clouds!".
"""

from __future__ import annotations

SHEET_CELLS = 4  # the sheet is SHEET_CELLS x SHEET_CELLS textures

TEX_FLAT_BOTTOM = (0,)
TEX_FOG = (1, 2, 3)
TEX_PUFFY = (4, 5, 6, 7, 8, 9)
TEX_WISPY = (10, 11, 12, 13, 14, 15)

CATEGORIES: dict[str, tuple[int, ...]] = {
    "flat_bottom": TEX_FLAT_BOTTOM,
    "fog": TEX_FOG,
    "puffy": TEX_PUFFY,
    "wispy": TEX_WISPY,
}
