"""Cockpit link drivers: the built-ins from a static table (no installed metadata needed),
third-party drivers from the `wxsky.inputs` entry-point group, failures as PluginError."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from wxsky.errors import PluginError
from wxsky.inputs import drivers
from wxsky.inputs.cockpit_link import CockpitLink

PLUGIN = """
from wxsky.inputs.cockpit_link import CockpitLink

class ThirdParty(CockpitLink):
    kind = "thirdparty"

class NotALink:
    pass
"""


@pytest.fixture
def plugin_dist(tmp_path: Path) -> Iterator[Path]:
    """A real installed distribution on sys.path (a dist-info folder importlib.metadata finds)
    that registers two drivers, one of them broken, and one shadowing a built-in name."""
    (tmp_path / "wxsky_thirdparty.py").write_text(PLUGIN, encoding="utf-8")
    info = tmp_path / "wxsky_thirdparty-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: wxsky-thirdparty\nVersion: 1.0\n", encoding="utf-8"
    )
    (info / "entry_points.txt").write_text(
        "[wxsky.inputs]\n"
        "thirdparty = wxsky_thirdparty:ThirdParty\n"
        "notalink = wxsky_thirdparty:NotALink\n"
        "missing = wxsky_no_such_module:Link\n"
        "serial = wxsky_thirdparty:ThirdParty\n",
        encoding="utf-8",
    )
    sys.path.insert(0, str(tmp_path))
    drivers.load_driver.cache_clear()
    try:
        yield tmp_path
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("wxsky_thirdparty", None)
        drivers.load_driver.cache_clear()


def test_the_built_ins_need_no_metadata() -> None:
    assert set(drivers.BUILTIN_DRIVERS) == {"serial", "can"}
    assert {"serial", "can"} <= set(drivers.driver_names())
    for kind in ("serial", "can"):
        cls = drivers.load_driver(kind)
        assert issubclass(cls, CockpitLink) and cls.kind == kind


def test_a_third_party_driver_is_found_by_entry_point(plugin_dist: Path) -> None:
    assert {"thirdparty", "notalink", "missing"} <= set(drivers.driver_names())
    assert drivers.load_driver("thirdparty").__name__ == "ThirdParty"
    # A plugin cannot take over a built-in's name.
    assert drivers.load_driver("serial").__module__ == "wxsky.inputs.serial_link"


def test_broken_drivers_are_plugin_errors_naming_them(plugin_dist: Path) -> None:
    with pytest.raises(PluginError, match=r"'missing' \(wxsky_no_such_module:Link\) failed"):
        drivers.load_driver("missing")
    with pytest.raises(PluginError, match=r"'notalink' .* is not a CockpitLink"):
        drivers.load_driver("notalink")
    with pytest.raises(PluginError, match=r"no cockpit input driver 'nope' \(known: can, "):
        drivers.load_driver("nope")
