"""Probe what this machine's GL/EGL offers for zero-copy textures (docs/protocol.md §6).

    .venv/bin/python tools/bench/probe_zero_copy.py [--json] [--call-anyway]

Opens the headless EGL context exactly as the daemon does (`wxsky.render.context`), then lists
the EGL client and display extensions and the GL extensions that bear on sharing textures
between processes, the EGL device behind the display and its DRM render node, whether
/dev/dri/renderD* and /dev/udmabuf exist, and tries a real export of a 16x16 texture
(eglCreateImageKHR from the texture, eglExportDMABUFImageQueryMESA, eglExportDMABUFImageMESA)
when the display lists the extensions. The last line says whether the daemon can export
its layer textures, or why not (the reason its `export_textures` answer gives).

--call-anyway also calls the export entry points on a display that does not list
EGL_MESA_image_dma_buf_export, in a child process, and reports how that ends (on Mesa 22.3's
llvmpipe: the child dies of SIGSEGV inside eglExportDMABUFImageQueryMESA, which is why the
daemon never calls an entry point whose extension is not listed).
"""

from __future__ import annotations

import argparse
import ctypes
import json
import signal
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from wxsky.render.context import create_context  # noqa: E402
from wxsky.render.texture_export import (  # noqa: E402
    EGL_GL_TEXTURE_2D_KHR,
    EGL_GL_TEXTURE_LEVEL_KHR,
    EGL_NONE,
    egl_error_name,
    fourcc_text,
    probe,
)


def call_export_unguarded() -> int:
    """The child of --call-anyway: the export calls with no extension check. Prints each step
    before it, so the parent sees where a crash happened."""
    ctx = create_context()
    egl = ctypes.CDLL("libEGL.so.1")
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglGetCurrentContext.restype = ctypes.c_void_p
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    egl.eglGetError.restype = ctypes.c_int
    dpy, cx = egl.eglGetCurrentDisplay(), egl.eglGetCurrentContext()
    vp, ip = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)
    addr = {
        n: egl.eglGetProcAddress(n.encode())
        for n in ("eglCreateImageKHR", "eglExportDMABUFImageQueryMESA", "eglExportDMABUFImageMESA")
    }
    for name, a in addr.items():
        print(f"step eglGetProcAddress({name}) = {'NULL' if not a else hex(a)}", flush=True)
    if not all(addr.values()):
        return 3
    create = ctypes.CFUNCTYPE(vp, vp, vp, ctypes.c_uint, vp, ip)(addr["eglCreateImageKHR"])
    query = ctypes.CFUNCTYPE(ctypes.c_uint, vp, vp, ip, ip, ctypes.POINTER(ctypes.c_uint64))(
        addr["eglExportDMABUFImageQueryMESA"]
    )
    export = ctypes.CFUNCTYPE(ctypes.c_uint, vp, vp, ip, ip, ip)(addr["eglExportDMABUFImageMESA"])
    tex = ctx.texture((16, 16), 4)
    attrs = (ctypes.c_int * 3)(EGL_GL_TEXTURE_LEVEL_KHR, 0, EGL_NONE)
    image = create(dpy, cx, EGL_GL_TEXTURE_2D_KHR, ctypes.c_void_p(tex.glo), attrs)
    print(f"step eglCreateImageKHR = {image} ({egl_error_name(egl.eglGetError())})", flush=True)
    if not image:
        return 4
    print("step calling eglExportDMABUFImageQueryMESA", flush=True)
    fourcc, planes = ctypes.c_int(0), ctypes.c_int(0)
    mods = (ctypes.c_uint64 * 4)()
    ok = query(dpy, image, fourcc, planes, mods)
    print(
        f"step eglExportDMABUFImageQueryMESA = {ok} ({egl_error_name(egl.eglGetError())}), "
        f"fourcc {fourcc_text(fourcc.value & 0xFFFFFFFF)} planes {planes.value} "
        f"modifier 0x{mods[0]:016x}",
        flush=True,
    )
    fds = (ctypes.c_int * 4)(-1, -1, -1, -1)
    strides, offsets = (ctypes.c_int * 4)(), (ctypes.c_int * 4)()
    print("step calling eglExportDMABUFImageMESA", flush=True)
    ok = export(dpy, image, fds, strides, offsets)
    print(
        f"step eglExportDMABUFImageMESA = {ok} ({egl_error_name(egl.eglGetError())}), "
        f"fds {list(fds)} strides {list(strides)} offsets {list(offsets)}",
        flush=True,
    )
    return 0


def call_anyway() -> str:
    proc = subprocess.run(
        [sys.executable, __file__, "--child-unguarded"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    steps = [line[5:] for line in proc.stdout.splitlines() if line.startswith("step ")]
    if proc.returncode < 0:
        end = f"killed by {signal.Signals(-proc.returncode).name}"
    else:
        end = f"exit {proc.returncode}"
    last = steps[-1] if steps else "(no step reached)"
    return f"unguarded export: {end} after: {last}"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--json", action="store_true", help="print the probe as one JSON object")
    p.add_argument(
        "--call-anyway",
        action="store_true",
        help="also call the export entry points unguarded, in a child process",
    )
    p.add_argument("--child-unguarded", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child_unguarded:
        return call_export_unguarded()
    ctx = create_context()
    found = probe(ctx)
    data = found.to_dict()
    if args.call_anyway:
        data["unguarded"] = call_anyway()
    if args.json:
        print(json.dumps(data))
        return 0
    print(f"GL renderer: {found.gl_renderer}")
    print(f"GL version: {found.gl_version}")
    print(f"EGL: {found.egl_vendor} {found.egl_version}")
    print(f"EGL client extensions: {' '.join(found.client_extensions)}")
    print(f"EGL display extensions (sharing): {' '.join(found.display_extensions) or '-'}")
    print(f"GL extensions (sharing): {' '.join(found.gl_extensions) or '-'}")
    print(f"EGL device extensions: {' '.join(found.device.get('extensions', [])) or '-'}")
    print(f"EGL device DRM render node: {found.device.get('drm_render_node') or '-'}")
    print(f"/dev/dri/renderD*: {' '.join(found.render_nodes) or 'none'}")
    print(f"/dev/udmabuf: {'yes' if found.udmabuf else 'no'}")
    print(f"export of a 16x16 texture: {found.export}")
    if args.call_anyway:
        print(data["unguarded"])
    if found.supported:
        print("zero-copy textures: available")
    else:
        print(f"zero-copy textures: unavailable: {found.reason}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
