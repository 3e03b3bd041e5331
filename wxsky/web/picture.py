"""The web station's live picture (docs/web.md): the latest published frame read from the
shared-memory segment and composited as a host does (`host/reference.py`), at the width the
pages ask for, as a JPEG. The **only** Pillow user.

A picture costs the daemon CPU beside its frames, so it is made small and cheap: the sky
and near layers are reduced to about the asked width before compositing (a tablet's
picture needs a quarter of a 1080p frame's pixels or fewer), the geometry of the composite
is kept while the camera and ring stand still (`host.compositor.CompositeCache`), it is made
in a child process below the frames' priority (`PictureWorker`), and the web part spaces
pictures so that making them takes a bounded share of one core (`app/web_part.py`)."""

from __future__ import annotations

import contextlib
import dataclasses
import io
import multiprocessing
import multiprocessing.process
import os
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection

import numpy as np
import numpy.typing as npt
from PIL import Image

from wxsky.errors import WxskyError
from wxsky.host.compositor import CompositeCache
from wxsky.host.compositor import Image as Layer
from wxsky.host.reference import HostFrame, host_frame
from wxsky.output.shm import FrameReader

MIN_WIDTH_PX = 160
MAX_WIDTH_PX = 1920
JPEG_QUALITY = 80  # sky gradients without visible blocks at a tenth of a PNG's size
# The widest picture composited; a wider page gets it scaled up. The composite's cost goes
# with its pixels (some 70 ms of one core at 480 x 270 with the geometry kept, on the
# development machine's CPU): wider would leave too few pictures a second in the CPU share.
MAX_COMPOSITE_PX = 480


@dataclass(frozen=True)
class Picture:
    jpeg: bytes
    frame_number: int
    width_px: int
    height_px: int
    took_s: float  # reading, compositing and encoding it, on this thread's clock


def box_reduced(image: Layer, step: int) -> Layer:
    """`image` (H, W, C) averaged over step x step blocks, its last row and column repeated
    to fill the last blocks: (ceil(H/step), ceil(W/step), C) of its dtype. The layers are
    premultiplied, so their mean is the mean of what they show. (A pixel taken every k-th
    would alias whatever is finer than k pixels: a far rain curtain's sheets came out as pin
    stripes.)"""
    h, w, c = image.shape
    hs, ws = -(-h // step), -(-w // step)
    full: npt.NDArray[np.generic] = image
    if (hs * step, ws * step) != (h, w):
        full = np.pad(image, ((0, hs * step - h), (0, ws * step - w), (0, 0)), mode="edge")
    if image.dtype == np.uint8:
        acc_type: type[np.generic] = np.uint16 if step * step * 255 <= 0xFFFF else np.uint32
    else:
        acc_type = np.float32
    # Strided adds, rows then columns: a fifteenth of the time of a mean over the blocks'
    # axes (7 against 100 ms for 1080p in fours), which walks the array element by element.
    rows = full.reshape(hs, step, ws * step, c)
    acc = rows[:, 0].astype(acc_type)
    for k in range(1, step):
        acc += rows[:, k]
    cols = acc.reshape(hs, ws, step, c)
    total = cols[:, :, 0].copy()
    for k in range(1, step):
        total += cols[:, :, k]
    if image.dtype == np.uint8:
        rounded: npt.NDArray[np.uint8] = ((total + step * step // 2) // (step * step)).astype(
            np.uint8
        )
        return rounded
    if image.dtype == np.float16:
        return (total / (step * step)).astype(np.float16)
    return (total / (step * step)).astype(np.float32)


def reduced(frame: HostFrame, width_px: int) -> HostFrame:
    """The frame with its screen layers (sky, near, the near layer's front) reduced by the
    smallest whole step k that makes them at most `width_px` wide (each pixel the mean of a
    k x k block), and its camera sized to match: the composite then costs 1/k² of the whole
    frame's."""
    layers, camera = frame.layers, frame.meta.camera
    step = max(1, -(-camera.width_px // max(1, width_px)))
    if step == 1:
        return frame
    front = layers.near_front
    small = dataclasses.replace(
        layers,
        sky=box_reduced(layers.sky, step),
        near=box_reduced(layers.near, step),
        near_front=None if front is None else box_reduced(front, step),
    )
    h, w = small.sky.shape[:2]
    # The same field of view over fewer pixels: every ray goes where the full frame's did.
    small_camera = dataclasses.replace(camera, width_px=w, height_px=h)
    meta = dataclasses.replace(frame.meta, camera=small_camera)
    return HostFrame(meta, small)


class PictureMaker:
    """Makes pictures of one segment's frames; used from one thread at a time. `close()`
    is idempotent."""

    def __init__(self, shm_name: str) -> None:
        self.shm_name = shm_name
        self._reader: FrameReader | None = None
        # While the camera and ring stand still (an IOS beside a parked aircraft, a host
        # between moves), which ray meets which quad is worked out once.
        self._cache = CompositeCache()

    def make(self, width_px: int) -> Picture:
        """The latest frame as a JPEG `width_px` wide (never wider than the frame), made from
        a composite at most MAX_COMPOSITE_PX wide.
        WxskyError or OSError when the segment cannot be read (the next call reopens it)."""
        t0 = time.thread_time()
        width_px = min(MAX_WIDTH_PX, max(MIN_WIDTH_PX, int(width_px)))
        try:
            reader = self._open()
            frame = host_frame(reader.read(timeout_s=1.0))
        except (WxskyError, OSError):
            self.close()
            raise
        small = reduced(frame, min(width_px, MAX_COMPOSITE_PX))
        rgba = small.composite(cache=self._cache)
        image = Image.fromarray(np.ascontiguousarray(rgba[..., :3]), "RGB")
        wanted = min(width_px, frame.meta.camera.width_px)
        if image.width != wanted:
            height = max(1, round(image.height * wanted / image.width))
            image = image.resize((wanted, height), Image.Resampling.BILINEAR)
        out = io.BytesIO()
        image.save(out, "JPEG", quality=JPEG_QUALITY)
        return Picture(
            out.getvalue(),
            frame.meta.frame_number,
            image.width,
            image.height,
            time.thread_time() - t0,
        )

    def _open(self) -> FrameReader:
        if self._reader is not None and not self._reader.is_current():
            self.close()
        if self._reader is None:
            self._reader = FrameReader.open(self.shm_name)
        return self._reader

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def __enter__(self) -> PictureMaker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class PictureWorker:
    """A PictureMaker in a child process below the frames' priority: compositing is numpy
    work that holds the GIL between its array operations, and on the daemon's own threads it
    held frames up (bench_web.py: 0.88x the frame rate with a thread, 1.0x with this). The
    child reads the segment as any host does. Started at the first picture; `make` blocks
    (call it off the loop); `close()` is idempotent."""

    def __init__(self, shm_name: str, nice: int = 10) -> None:
        self.shm_name = shm_name
        self.nice = nice
        self._proc: multiprocessing.process.BaseProcess | None = None
        self._conn: Connection | None = None

    def make(self, width_px: int) -> Picture:
        """As PictureMaker.make, in the child; WxskyError (one line) for what it could not
        do, the child itself gone included (the next call starts another)."""
        if self._conn is None:
            self._start()
        assert self._conn is not None
        try:
            self._conn.send(int(width_px))
            kind, value = self._conn.recv()
        except (EOFError, OSError) as exc:
            self.close()
            raise WxskyError(f"the picture process ended: {exc or 'no answer'}") from None
        if kind == "error":
            raise WxskyError(str(value))
        assert isinstance(value, Picture)
        return value

    def _start(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(
            target=_serve,
            args=(child, self.shm_name, self.nice),
            name="wxsky-web-picture",
            daemon=True,
        )
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent

    def close(self, wait_s: float = 1.0) -> None:
        conn, proc = self._conn, self._proc
        self._conn = self._proc = None
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.send(None)
            conn.close()
        if proc is not None:
            proc.join(wait_s)
            if proc.is_alive():
                proc.kill()
                proc.join(wait_s)


def _serve(conn: Connection, shm_name: str, nice: int) -> None:
    """The child: a picture for each width asked, until None or the pipe closes."""
    with contextlib.suppress(OSError):
        os.nice(nice)
    with PictureMaker(shm_name) as maker:
        while True:
            try:
                width = conn.recv()
            except (EOFError, OSError, KeyboardInterrupt):
                return
            if width is None:
                return
            try:
                conn.send(("ok", maker.make(width)))
            except (WxskyError, OSError, ValueError) as exc:
                conn.send(("error", f"no picture: {exc}"))
