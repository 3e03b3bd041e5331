#!/usr/bin/env python3
"""Write the OpenSceneGraph plugin's example terrain: a 24 km square of rolling ground with a
ridge 4 km north of the site rising to 700 m, in wxsky's frame (x east, y north, z up metres
about the daemon's site), in OSG's own text format (.osg, which every OSG application reads).

    .venv/bin/python tools/generate/osg_terrain.py plugins/osg/examples/terrain.osg

Its colours are lit once here by a sun in the south-west (lighting off in the file), so any
viewer shows the same terrain: OSG's default headlight would leave the ground nearly black
seen level. The ridge covers the lower part of a view north from near the ground, so the
plugin's pictures have terrain in front of clouds and sky above it (tests/test_osg_plugin.py).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

HALF_M = 12_000.0
STEP_M = 400.0
RIDGE_NORTH_M = 4_000.0
RIDGE_M = 700.0


def height_m(x: float, y: float) -> float:
    """Rolling ground a few tens of metres high, and the ridge along y = RIDGE_NORTH_M."""
    roll = 25.0 * math.sin(x / 1900.0) * math.cos(y / 2300.0) + 15.0 * math.sin((x + y) / 900.0)
    ridge = (
        RIDGE_M
        * math.exp(-(((y - RIDGE_NORTH_M) / 900.0) ** 2))
        * (0.75 + 0.25 * math.cos(x / 3100.0))
    )
    return max(0.0, 20.0 + roll) + ridge


SUN = (-0.45, -0.55, 0.70)  # toward the sun, from the south-west and 44 degrees up


def colour(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Green lowland to brown rock, lit by SUN with some sky light."""
    e = 10.0
    dzdx = (height_m(x + e, y) - height_m(x - e, y)) / (2 * e)
    dzdy = (height_m(x, y + e) - height_m(x, y - e)) / (2 * e)
    n = (-dzdx, -dzdy, 1.0)
    ln = math.sqrt(sum(c * c for c in n))
    sl = math.sqrt(sum(c * c for c in SUN))
    lit = 0.35 + 0.65 * max(0.0, sum(a * b for a, b in zip(n, SUN, strict=True)) / (ln * sl))
    t = min(1.0, max(0.0, (z - 40.0) / RIDGE_M))
    low, high = (0.30, 0.45, 0.20), (0.55, 0.48, 0.40)
    return tuple(lit * (a + (b - a) * t) for a, b in zip(low, high, strict=True))  # type: ignore[return-value]


def write_osg(path: Path) -> None:
    n = int(2 * HALF_M / STEP_M) + 1
    verts, colours, index = [], [], []
    for j in range(n):
        for i in range(n):
            x, y = -HALF_M + i * STEP_M, -HALF_M + j * STEP_M
            z = height_m(x, y)
            verts.append(f"          {x:.1f} {y:.1f} {z:.2f}")
            r, g, b = colour(x, y, z)
            colours.append(f"          {r:.4f} {g:.4f} {b:.4f} 1")
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i
            index.append(f"          {a} {a + 1} {a + n + 1} {a} {a + n + 1} {a + n}")
    out = [
        "Geode {",
        "  nodeMask 0xffffffff",
        "  cullingActive TRUE",
        "  StateSet {",
        "    GL_LIGHTING OFF",
        "  }",
        "  num_drawables 1",
        "  Geometry {",
        "    DataVariance STATIC",
        "    useDisplayList TRUE",
        "    useVertexBufferObjects FALSE",
        "    PrimitiveSets 1",
        "    {",
        f"      DrawElementsUInt TRIANGLES {6 * (n - 1) * (n - 1)}",
        "      {",
        *index,
        "      }",
        "    }",
        f"    VertexArray Vec3Array {n * n}",
        "    {",
        *verts,
        "    }",
        "    ColorBinding PER_VERTEX",
        f"    ColorArray Vec4Array {n * n}",
        "    {",
        *colours,
        "    }",
        "  }",
        "}",
    ]
    path.write_text(
        "# wxsky OSG example terrain (tools/generate/osg_terrain.py)\n" + "\n".join(out) + "\n"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="the .osg file to write")
    write_osg(ap.parse_args().out)


if __name__ == "__main__":
    main()
