#!/usr/bin/env python3
"""Build the sky pass's textures shipped in wxsky/render/data/.

    .venv/bin/python tools/generate/build_sky_textures.py          # write the files
    .venv/bin/python tools/generate/build_sky_textures.py --check  # exit 1: shipped PNGs drift

Writes wxsky/render/data/sky_stars.png (the star cube map, six faces in one vertical strip),
sky_galaxy.png (the Milky Way's glow, grey in RGB, A = 255), sky_dome_noise.png (the cloud
dome's four noise fields) and sky_sunset.png (the dome's sunset tint over the sunset control
and the height in the sky, A = 255), all RGBA8, from the one generator,
`wxsky.render.sky_texture_gen.build_sky_textures`, with its fixed seeds. `--check` regenerates in
memory and compares the shipped PNGs' pixels, so CI catches a generator change whose files were
not rebuilt; `--out DIR` writes to (or checks) another folder. After rebuilding, regenerate the
goldens (tools/generate/regen_goldens.py): the sky is drawn with these textures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:  # run from a checkout without installing; `tools.*` too
    sys.path.insert(0, str(ROOT))

from tools.generate.shipped_files import write_or_check  # noqa: E402
from wxsky.render.sky_texture_gen import SKY_FILES, build_sky_textures  # noqa: E402
from wxsky.render.sky_textures import DATA_DIR  # noqa: E402

DATA = ROOT / "wxsky" / "render" / DATA_DIR


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--check", action="store_true", help="compare with the shipped files, write nothing"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="folder to write or check (default: the package's)"
    )
    args = parser.parse_args(argv)
    out: Path = args.out if args.out is not None else DATA
    images = build_sky_textures()
    assert tuple(images) == SKY_FILES
    return write_or_check(
        images, out, check=args.check, tool="tools/generate/build_sky_textures.py"
    )


if __name__ == "__main__":
    sys.exit(main())
