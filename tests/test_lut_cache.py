"""The atmosphere's tables kept on disk (wxsky/engine/lut_cache.py): read back exactly as
made, named by the code that made them, made anew when a file is spoilt, bounded, and off
(with one log line) where the folder cannot be written."""

from __future__ import annotations

import ast
import importlib
import inspect
import logging
import os
from pathlib import Path

import numpy as np
import pytest

from wxsky.engine import lut_cache
from wxsky.scene import atmosphere as atm

KEY = atm.atmosphere_key(20.0, 30_000.0, 50.0, 2.0)


@pytest.fixture
def folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv(lut_cache.CACHE_ENV, str(tmp_path))
    monkeypatch.setattr(lut_cache, "_off", False)
    return tmp_path / "atmosphere"


def _same(a: atm.AtmosphereLuts, b: atm.AtmosphereLuts) -> None:
    assert a.key == b.key and a.medium == b.medium
    for name in atm.TABLE_SHAPES:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert not getattr(b, name).flags.writeable


def test_a_set_is_read_back_exactly_as_made(folder: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    made = lut_cache.cached_luts(KEY)
    path = lut_cache.file_for(folder, KEY)
    assert path.is_file()
    _same(atm.build_luts(KEY), made)

    def no_build(key: atm.AtmosphereKey) -> atm.AtmosphereLuts:
        raise AssertionError(f"{key} made again, not read back")

    monkeypatch.setattr(atm, "build_luts", no_build)
    again = lut_cache.cached_luts(KEY)
    _same(made, again)
    assert again.serial != made.serial  # a new set for this process's textures


def test_other_code_or_another_key_is_another_file(
    folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    first = lut_cache.file_for(folder, KEY)
    other = atm.atmosphere_key(20.0, 30_000.0, 50.0, 900.0)
    assert lut_cache.file_for(folder, other) != first
    monkeypatch.setattr(lut_cache, "_digest", "0" * 16)
    assert lut_cache.file_for(folder, KEY) != first


def test_the_digest_covers_every_wxsky_module_the_atmosphere_imports() -> None:
    """Each name the atmosphere takes from wxsky is defined in a file of CODE_FILES."""
    source = Path(atm.__file__).read_text(encoding="utf-8")
    package = Path(atm.__file__).resolve().parents[1]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("wxsky"):
            module = importlib.import_module(node.module or "")
            for alias in node.names:
                defined = getattr(getattr(module, alias.name), "__module__", node.module)
                found.append(inspect.getfile(importlib.import_module(defined)))
        elif isinstance(node, ast.Import):
            found += [
                inspect.getfile(importlib.import_module(a.name))
                for a in node.names
                if a.name.startswith("wxsky")
            ]
    assert found, "the atmosphere imports nothing from wxsky: the check would check nothing"
    for name in found:
        rel = Path(name).resolve().relative_to(package).as_posix()
        assert rel in lut_cache.CODE_FILES, f"{rel}: not in lut_cache.CODE_FILES"


def test_a_spoilt_file_is_made_anew_with_one_line(
    folder: Path, caplog: pytest.LogCaptureFixture
) -> None:
    made = lut_cache.cached_luts(KEY)
    path = lut_cache.file_for(folder, KEY)
    whole = path.read_bytes()
    for spoilt in (whole[: len(whole) // 2], b"", whole.replace(b"sky_view", b"sky_vieW")):
        path.write_bytes(spoilt)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="wxsky.engine.lut_cache"):
            again = lut_cache.cached_luts(KEY)
        _same(made, again)
        lines = [r.getMessage() for r in caplog.records]
        assert len(lines) == 1 and str(path) in lines[0] and "anew" in lines[0], lines
        assert path.read_bytes() == whole  # written over with the good set


def test_a_folder_that_cannot_be_written_turns_the_cache_off_with_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(lut_cache.CACHE_ENV, str(blocker))
    monkeypatch.setattr(lut_cache, "_off", False)
    with caplog.at_level(logging.WARNING, logger="wxsky.engine.lut_cache"):
        first = lut_cache.cached_luts(KEY)
        second = lut_cache.cached_luts(atm.atmosphere_key(30.0, 30_000.0, 50.0, 2.0))
    _same(atm.build_luts(KEY), first)
    assert second.key != first.key
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "off" in lines[0] and str(blocker) in lines[0], lines
    assert blocker.read_text() == "not a folder"


def test_an_empty_setting_turns_the_cache_off(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(lut_cache.CACHE_ENV, "")
    assert lut_cache.cache_dir() is None
    monkeypatch.delenv(lut_cache.CACHE_ENV)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert lut_cache.cache_dir() == tmp_path / "wxsky" / "atmosphere"


def test_the_least_recently_used_files_go_first(tmp_path: Path) -> None:
    for i in range(5):
        name = tmp_path / f"{i}.npz"
        name.write_bytes(b"x" * 1000)
        os.utime(name, (1000.0 + i, 1000.0 + i))
    os.utime(tmp_path / "0.npz", (2000.0, 2000.0))  # read back lately
    (tmp_path / ".7.npz.9.part").write_bytes(b"x" * 5000)  # another process's write
    lut_cache._trim(tmp_path, max_bytes=2500)
    assert sorted(p.name for p in tmp_path.glob("*.npz")) == ["0.npz", "4.npz"]
    assert (tmp_path / ".7.npz.9.part").exists()
