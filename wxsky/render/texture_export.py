"""Zero-copy textures: handing the layers to a host as dma-bufs instead of through shared memory.

The render thread's GL context came from EGL (`context.py`); with EGL_KHR_gl_texture_2D_image
a GL texture becomes an EGLImage, and with EGL_MESA_image_dma_buf_export an EGLImage becomes
dma-buf file descriptors (fourcc, modifier, per-plane stride and offset) that a host on the
unix socket receives (SCM_RIGHTS, `output/transport.py`) and imports with
EGL_EXT_image_dma_buf_import: both processes then use the same GPU memory.

`probe` says whether that works on this context and, when not, why, in one line: the daemon
answers `export_textures` with that reason (docs/protocol.md §6) and the host keeps using the
segment. `SlotTextures` are the exported textures: one per layer per segment slot, at the
layer's capacity, filled by a GPU copy of the layers each frame while a host uses them, so a
host never samples a texture the daemon is drawing into (the segment's seqlock says which
slot is whole, as for its pixels).

Only ctypes on libEGL here, and only entry points whose extension the display lists: Mesa
22.3's llvmpipe crashes (SIGSEGV) in eglExportDMABUFImageQueryMESA when the display does not
list EGL_MESA_image_dma_buf_export (`tools/bench/probe_zero_copy.py --call-anyway` shows it).
"""

from __future__ import annotations

import contextlib
import ctypes
import glob
import logging
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import moderngl

from wxsky.errors import RenderError
from wxsky.render.context import release_framebuffer

if TYPE_CHECKING:
    from wxsky.render.renderer import Renderer

log = logging.getLogger(__name__)

EGL_SUCCESS = 0x3000
EGL_VENDOR = 0x3053
EGL_VERSION = 0x3054
EGL_EXTENSIONS = 0x3055
EGL_NONE = 0x3038
EGL_GL_TEXTURE_2D_KHR = 0x30B1
EGL_GL_TEXTURE_LEVEL_KHR = 0x30BC
EGL_DEVICE_EXT = 0x322C
EGL_DRM_DEVICE_FILE_EXT = 0x3233
EGL_DRM_RENDER_NODE_FILE_EXT = 0x3377
DRM_FORMAT_MOD_INVALID = 0x00FFFFFFFFFFFFFF
# The fourccs the slot textures export as (the driver names its own; these are what the
# segment's formats are, for checking it): DRM_FORMAT_ABGR8888 'AB24' for RGBA8 (bytes R, G,
# B, A), DRM_FORMAT_ABGR16161616F 'AB4H' for RGBA16F (half floats R, G, B, A).
DRM_FORMAT_ABGR8888 = 0x34324241
DRM_FORMAT_ABGR16161616F = 0x48344241
LAYER_FOURCC = {"rgba8": DRM_FORMAT_ABGR8888, "rgba16f": DRM_FORMAT_ABGR16161616F}
# The texture dtype of each segment format (moderngl's names).
_TEXTURE_DTYPE = {"rgba8": "f1", "rgba16f": "f2"}
MAX_PLANES = 4

_EGL_ERRORS = {
    0x3000: "EGL_SUCCESS",
    0x3001: "EGL_NOT_INITIALIZED",
    0x3002: "EGL_BAD_ACCESS",
    0x3003: "EGL_BAD_ALLOC",
    0x3004: "EGL_BAD_ATTRIBUTE",
    0x3005: "EGL_BAD_CONFIG",
    0x3006: "EGL_BAD_CONTEXT",
    0x3007: "EGL_BAD_CURRENT_SURFACE",
    0x3008: "EGL_BAD_DISPLAY",
    0x3009: "EGL_BAD_MATCH",
    0x300A: "EGL_BAD_NATIVE_PIXMAP",
    0x300B: "EGL_BAD_NATIVE_WINDOW",
    0x300C: "EGL_BAD_PARAMETER",
    0x300D: "EGL_BAD_SURFACE",
    0x300E: "EGL_CONTEXT_LOST",
}

# What the probe reports of each list (the rest of a driver's extensions do not bear on
# sharing textures between processes).
EGL_SHARING = (
    "EGL_KHR_image_base",
    "EGL_KHR_gl_texture_2D_image",
    "EGL_MESA_image_dma_buf_export",
    "EGL_EXT_image_dma_buf_import",
    "EGL_EXT_image_dma_buf_import_modifiers",
    "EGL_KHR_fence_sync",
    "EGL_KHR_wait_sync",
    "EGL_ANDROID_native_fence_sync",
    "EGL_MESA_drm_image",
)
GL_SHARING = (
    "GL_OES_EGL_image",
    "GL_EXT_EGL_image_storage",
    "GL_EXT_memory_object",
    "GL_EXT_memory_object_fd",
    "GL_EXT_semaphore",
    "GL_EXT_semaphore_fd",
    "GL_EXT_EGL_sync",
)
# What the daemon's export needs, in the order a reason names the first one missing.
EXPORT_NEEDS = (
    "EGL_KHR_image_base",
    "EGL_KHR_gl_texture_2D_image",
    "EGL_MESA_image_dma_buf_export",
)


def fourcc_text(code: int) -> str:
    """DRM fourcc as its four characters ('AB24' for DRM_FORMAT_ABGR8888)."""
    return "".join(chr((code >> (8 * i)) & 0xFF) for i in range(4))


def egl_error_name(code: int) -> str:
    return _EGL_ERRORS.get(code, f"0x{code:04x}")


class _Egl:
    """libEGL through ctypes, for the display and context current on this thread."""

    def __init__(self) -> None:
        try:
            lib = ctypes.CDLL("libEGL.so.1")
        except OSError as exc:
            raise RenderError(f"cannot load libEGL.so.1: {exc}") from exc
        self.lib = lib
        lib.eglGetCurrentDisplay.restype = ctypes.c_void_p
        lib.eglGetCurrentContext.restype = ctypes.c_void_p
        lib.eglGetError.restype = ctypes.c_int
        lib.eglQueryString.restype = ctypes.c_char_p
        lib.eglQueryString.argtypes = [ctypes.c_void_p, ctypes.c_int]
        lib.eglGetProcAddress.restype = ctypes.c_void_p
        lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        self.display = lib.eglGetCurrentDisplay()
        self.context = lib.eglGetCurrentContext()
        if not self.display or not self.context:
            raise RenderError(
                "no EGL context is current on this thread (the GL context is not EGL)"
            )

    def query(self, display: int | None, name: int) -> str:
        raw = self.lib.eglQueryString(display, name)
        return raw.decode("ascii", "replace") if raw else ""

    def error(self) -> str:
        return egl_error_name(int(self.lib.eglGetError()))

    def proc(self, name: str, restype: Any, *argtypes: Any) -> Any:
        """The entry point `name`, typed, or None. Call only one whose extension is listed."""
        address = self.lib.eglGetProcAddress(name.encode("ascii"))
        if not address:
            return None
        return ctypes.CFUNCTYPE(restype, *argtypes)(address)


def _device_info(egl: _Egl, client: set[str]) -> dict[str, Any]:
    """The EGL device behind the display: its extensions and DRM node files."""
    out: dict[str, Any] = {"extensions": [], "drm_device_file": None, "drm_render_node": None}
    if "EGL_EXT_device_query" not in client:
        return out
    attrib = egl.proc(
        "eglQueryDisplayAttribEXT",
        ctypes.c_uint,
        ctypes.c_void_p,
        ctypes.c_int,
        ctypes.POINTER(ctypes.c_void_p),
    )
    string = egl.proc("eglQueryDeviceStringEXT", ctypes.c_char_p, ctypes.c_void_p, ctypes.c_int)
    device = ctypes.c_void_p()
    if attrib is None or string is None or not attrib(egl.display, EGL_DEVICE_EXT, device):
        egl.error()  # clear it
        return out
    ext = string(device, EGL_EXTENSIONS)
    out["extensions"] = sorted((ext or b"").decode("ascii", "replace").split())
    for key, name, need in (
        ("drm_device_file", EGL_DRM_DEVICE_FILE_EXT, "EGL_EXT_device_drm"),
        ("drm_render_node", EGL_DRM_RENDER_NODE_FILE_EXT, "EGL_EXT_device_drm_render_node"),
    ):
        if need in out["extensions"]:
            value = string(device, name)
            out[key] = value.decode("ascii", "replace") if value else None
            egl.error()  # a device without that node reports EGL_BAD_PARAMETER: not ours
    return out


def _device_words(device: dict[str, Any]) -> str:
    kind = (
        "the Mesa software device"
        if "EGL_MESA_device_software" in device.get("extensions", ())
        else "an EGL device"
    )
    node = device.get("drm_render_node")
    return f"{kind}, render node {node}" if node else f"{kind}, no DRM render node"


@dataclass(frozen=True)
class ExportedImage:
    """One texture as dma-buf planes; the fds belong to this object until `close`."""

    fourcc: int
    modifier: int
    fds: tuple[int, ...]
    strides: tuple[int, ...]
    offsets: tuple[int, ...]
    image: int = field(repr=False)

    def describe(self) -> str:
        planes = ", ".join(
            f"plane {i}: stride {s} offset {o}"
            for i, (s, o) in enumerate(zip(self.strides, self.offsets, strict=True))
        )
        return f"fourcc {fourcc_text(self.fourcc)} modifier 0x{self.modifier:016x}, {planes}"


class DmaBufExporter:
    """EGLImage -> dma-buf for textures of the context current on this (the render) thread.
    Build with `DmaBufExporter.create`, which raises RenderError naming what is missing."""

    def __init__(self, egl: _Egl, display_extensions: set[str]) -> None:
        self._egl = egl
        vp, ip = ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)
        self._create = egl.proc("eglCreateImageKHR", vp, vp, vp, ctypes.c_uint, vp, ip)
        self._destroy = egl.proc("eglDestroyImageKHR", ctypes.c_uint, vp, vp)
        self._query = self._export = None
        if "EGL_MESA_image_dma_buf_export" in display_extensions:
            self._query = egl.proc(
                "eglExportDMABUFImageQueryMESA",
                ctypes.c_uint,
                vp,
                vp,
                ip,
                ip,
                ctypes.POINTER(ctypes.c_uint64),
            )
            self._export = egl.proc("eglExportDMABUFImageMESA", ctypes.c_uint, vp, vp, ip, ip, ip)
        self._images: list[ExportedImage] = []

    @classmethod
    def create(cls) -> DmaBufExporter:
        egl = _Egl()
        ext = set(egl.query(egl.display, EGL_EXTENSIONS).split())
        missing = [name for name in EXPORT_NEEDS if name not in ext]
        if missing:
            raise RenderError(f"the EGL display does not offer {', '.join(missing)}")
        exporter = cls(egl, ext)
        for what, fn in (
            ("eglCreateImageKHR", exporter._create),
            ("eglDestroyImageKHR", exporter._destroy),
            ("eglExportDMABUFImageQueryMESA", exporter._query),
            ("eglExportDMABUFImageMESA", exporter._export),
        ):
            if fn is None:
                raise RenderError(f"eglGetProcAddress finds no {what}")
        return exporter

    def export(self, texture: moderngl.Texture) -> ExportedImage:
        """The texture's level 0 as dma-buf planes; RenderError names the call that failed."""
        egl = self._egl
        assert self._create and self._destroy and self._query and self._export
        egl.error()  # start from EGL_SUCCESS, so the code below is this call's
        attrs = (ctypes.c_int * 3)(EGL_GL_TEXTURE_LEVEL_KHR, 0, EGL_NONE)
        image = self._create(
            egl.display, egl.context, EGL_GL_TEXTURE_2D_KHR, ctypes.c_void_p(texture.glo), attrs
        )
        if not image:
            raise RenderError(f"eglCreateImageKHR(EGL_GL_TEXTURE_2D_KHR) failed: {egl.error()}")
        fourcc, planes = ctypes.c_int(0), ctypes.c_int(0)
        modifiers = (ctypes.c_uint64 * MAX_PLANES)()
        if not self._query(egl.display, image, fourcc, planes, modifiers):
            why = egl.error()
            self._destroy(egl.display, image)
            raise RenderError(f"eglExportDMABUFImageQueryMESA failed: {why}")
        n = planes.value
        if not 1 <= n <= MAX_PLANES:
            self._destroy(egl.display, image)
            raise RenderError(f"eglExportDMABUFImageQueryMESA says {n} planes (1..{MAX_PLANES})")
        fds = (ctypes.c_int * MAX_PLANES)(*([-1] * MAX_PLANES))
        strides = (ctypes.c_int * MAX_PLANES)()
        offsets = (ctypes.c_int * MAX_PLANES)()
        if not self._export(egl.display, image, fds, strides, offsets):
            why = egl.error()
            self._destroy(egl.display, image)
            raise RenderError(f"eglExportDMABUFImageMESA failed: {why}")
        # A plane in the first plane's buffer comes back as -1 (the extension's words): the
        # importer passes the first fd again for it.
        plane_fds = tuple(fds[i] if fds[i] >= 0 else fds[0] for i in range(n))
        if plane_fds[0] < 0:
            self._destroy(egl.display, image)
            raise RenderError("eglExportDMABUFImageMESA gave no file descriptor")
        exported = ExportedImage(
            fourcc=fourcc.value & 0xFFFFFFFF,
            modifier=int(modifiers[0]),
            fds=plane_fds,
            strides=tuple(int(strides[i]) for i in range(n)),
            offsets=tuple(int(offsets[i]) for i in range(n)),
            image=int(image),
        )
        self._images.append(exported)
        return exported

    def close(self) -> None:
        """Close every exported fd and destroy the images (the render thread, context current)."""
        for item in self._images:
            for fd in set(item.fds):
                with contextlib.suppress(OSError):
                    os.close(fd)
            if self._destroy is not None:
                self._destroy(self._egl.display, ctypes.c_void_p(item.image))
        self._images.clear()


@dataclass(frozen=True)
class ExportProbe:
    """What the current EGL/GL context offers for sharing textures with another process."""

    gl_renderer: str
    gl_version: str
    egl_vendor: str
    egl_version: str
    client_extensions: tuple[str, ...]
    display_extensions: tuple[str, ...]  # the sharing ones (EGL_SHARING) the display lists
    gl_extensions: tuple[str, ...]  # the sharing ones (GL_SHARING) the context lists
    device: dict[str, Any]
    render_nodes: tuple[str, ...]
    udmabuf: bool
    export: str  # what a 16x16 export gave, or where it stopped
    reason: str | None  # None when textures can be exported; else why not, one line

    @property
    def supported(self) -> bool:
        return self.reason is None

    def to_dict(self) -> dict[str, Any]:
        return {
            "supported": self.supported,
            "reason": self.reason,
            "gl_renderer": self.gl_renderer,
            "gl_version": self.gl_version,
            "egl_vendor": self.egl_vendor,
            "egl_version": self.egl_version,
            "client_extensions": list(self.client_extensions),
            "display_extensions": list(self.display_extensions),
            "gl_extensions": list(self.gl_extensions),
            "device": self.device,
            "render_nodes": list(self.render_nodes),
            "udmabuf": self.udmabuf,
            "export": self.export,
        }


def probe(ctx: moderngl.Context) -> ExportProbe:
    """Probe the context current on this thread (ctx, made by `create_context`), including a
    real export of a 16x16 texture when the display lists the extensions. Never raises for a
    missing feature: the result's `reason` says it."""
    renderer = str(ctx.info.get("GL_RENDERER", ""))
    version = str(ctx.info.get("GL_VERSION", ""))
    gl_ext = tuple(name for name in GL_SHARING if name in ctx.extensions)
    nodes = tuple(sorted(glob.glob("/dev/dri/renderD*")))
    udmabuf = os.path.exists("/dev/udmabuf")
    try:
        egl = _Egl()
    except RenderError as exc:
        return ExportProbe(
            renderer, version, "", "", (), (), gl_ext, {}, nodes, udmabuf, "not tried", str(exc)
        )
    client = set(egl.query(None, EGL_EXTENSIONS).split())
    display = set(egl.query(egl.display, EGL_EXTENSIONS).split())
    device = _device_info(egl, client)
    vendor, egl_version = egl.query(egl.display, EGL_VENDOR), egl.query(egl.display, EGL_VERSION)
    reason: str | None = None
    export = "not tried"
    missing = [name for name in EXPORT_NEEDS if name not in display]
    if missing:
        reason = (
            f"no {', '.join(missing)} on {renderer} ({version}; EGL {vendor} {egl_version}, "
            f"{_device_words(device)}): use the shm segment"
        )
        export = f"not called: the display does not list {', '.join(missing)}"
    else:
        tex = ctx.texture((16, 16), 4)
        exporter: DmaBufExporter | None = None
        try:
            exporter = DmaBufExporter.create()
            image = exporter.export(tex)
            export = f"ok: {image.describe()}"
        except RenderError as exc:
            export = str(exc)
            reason = f"exporting a texture on {renderer} failed: {exc}: use the shm segment"
        finally:
            if exporter is not None:
                exporter.close()
            tex.release()
    return ExportProbe(
        gl_renderer=renderer,
        gl_version=version,
        egl_vendor=vendor,
        egl_version=egl_version,
        client_extensions=tuple(sorted(client)),
        display_extensions=tuple(name for name in EGL_SHARING if name in display),
        gl_extensions=gl_ext,
        device=device,
        render_nodes=nodes,
        udmabuf=udmabuf,
        export=export,
        reason=reason,
    )


@dataclass
class _SlotLayer:
    name: str
    slot: int
    texture: moderngl.Texture
    fbo: moderngl.Framebuffer
    image: ExportedImage | None = None


class SlotTextures:
    """One texture per (segment slot, layer), at the layer's capacity, on the render thread's
    context; exported as dma-bufs when an exporter is given (a GPU), plain textures otherwise
    (what the copies can be tested with on llvmpipe). `formats`: each layer's segment format
    (rgba8 when not named): RGBA16F layers get half-float textures, which a driver exports
    as 'AB4H' (DRM_FORMAT_ABGR16161616F) where it can.

    Per frame, for the slot the segment writer is filling: `copy` each layer it publishes
    (a GPU blit from the renderer's target, row 0 the image's top as in the segment), then
    the renderer's glFinish before the segment publish, so the slot is complete in GPU memory
    when its seqlock says it is."""

    def __init__(
        self,
        ctx: moderngl.Context,
        layers: Sequence[tuple[str, int, int]],
        slot_count: int = 2,
        exporter: DmaBufExporter | None = None,
        formats: Mapping[str, str] | None = None,
    ) -> None:
        self._ctx = ctx
        self._exporter = exporter
        self.slot_count = slot_count
        self._layers: dict[tuple[int, str], _SlotLayer] = {}
        self._capacity = {name: (w, h) for name, w, h in layers}
        self._format = {name: (formats or {}).get(name, "rgba8") for name, _, _ in layers}
        self._written: dict[tuple[int, str], int] = {}  # version of what `write` last put there
        try:
            for slot in range(slot_count):
                for name, width, height in layers:
                    tex = ctx.texture((width, height), 4, dtype=_TEXTURE_DTYPE[self._format[name]])
                    # One level and no mipmap filtering: a complete texture, as
                    # EGL_KHR_gl_texture_2D_image wants for level 0.
                    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
                    entry = _SlotLayer(name, slot, tex, ctx.framebuffer(color_attachments=[tex]))
                    self._layers[(slot, name)] = entry
                    # Cleared once, so a layer a frame leaves out shows nothing stale.
                    entry.fbo.clear(0.0, 0.0, 0.0, 0.0)
                    if exporter is not None:
                        entry.image = exporter.export(tex)
        except BaseException:
            self.close()
            raise

    def descriptors(self) -> tuple[list[dict[str, Any]], tuple[int, ...]]:
        """Each texture's description (protocol §6) and the fds to send, in `fd` index order."""
        out: list[dict[str, Any]] = []
        fds: list[int] = []
        for entry in self._layers.values():
            if entry.image is None:
                raise RenderError("these slot textures were not exported")
            width, height = self._capacity[entry.name]
            planes = []
            for fd, stride, offset in zip(
                entry.image.fds, entry.image.strides, entry.image.offsets, strict=True
            ):
                if fd not in fds:
                    fds.append(fd)
                planes.append({"fd": fds.index(fd), "stride": stride, "offset": offset})
            out.append(
                {
                    "layer": entry.name,
                    "slot": entry.slot,
                    "width": width,
                    "height": height,
                    "fourcc": entry.image.fourcc,
                    "modifier": entry.image.modifier,
                    "planes": planes,
                }
            )
        return out, tuple(fds)

    def copy(self, slot: int, layer: str, source: moderngl.Framebuffer) -> None:
        """Blit `source` (exactly the frame's width x height) into the corner of the slot's
        texture: texel row 0 is the image's top row, as in the segment."""
        self._ctx.copy_framebuffer(self._layers[(slot, layer)].fbo, source)

    def write(
        self, slot: int, layer: str, pixels: bytes, width: int, height: int, version: int
    ) -> None:
        """Upload a layer made on the CPU (the shadow map) into the corner of the slot's
        texture, rows as in the segment; skipped when that slot already holds `version`."""
        if self._written.get((slot, layer)) == version:
            return
        self._layers[(slot, layer)].texture.write(pixels, viewport=(0, 0, width, height))
        self._written[(slot, layer)] = version

    def read(self, slot: int, layer: str, width: int, height: int) -> bytes:
        """The slot texture's top-left width x height, rows as in the segment (for tests):
        bytes for RGBA8, half floats for RGBA16F, as the segment holds them."""
        fbo = self._layers[(slot, layer)].fbo
        dtype = _TEXTURE_DTYPE[self._format[layer]]
        data: bytes = fbo.read(
            viewport=(0, 0, width, height), components=4, alignment=1, dtype=dtype
        )
        return data

    def close(self) -> None:
        if self._exporter is not None:
            self._exporter.close()
        for entry in self._layers.values():
            release_framebuffer(entry.fbo)
            entry.texture.release()
        self._layers.clear()


class SlotExport:
    """`SlotTextures` bound to the renderer and the slot the segment writer is filling: what
    `app/frame_publish.publish_plan` takes as its `export`."""

    def __init__(self, slots: SlotTextures, renderer: Renderer, slot: int) -> None:
        self._slots = slots
        self._renderer = renderer
        self._slot = slot

    def copy(self, layer: str, source: str) -> None:
        self._slots.copy(self._slot, layer, self._renderer.target_framebuffer(source))

    def write(self, layer: str, pixels: bytes, width: int, height: int, version: int) -> None:
        self._slots.write(self._slot, layer, pixels, width, height, version)

    def finish(self) -> None:
        # glFinish, GIL-free: the copies are in GPU memory before the seqlock says so. No
        # dma-buf implicit fencing is relied on (NVIDIA's driver does none).
        self._renderer.finish()
