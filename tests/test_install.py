"""wxsky installed from a wheel, away from the checkout, finds everything it ships: presets,
cloud models, the station table, shaders and textures (package data through
importlib.resources), and its built-in cockpit drivers (a static table, no entry points)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# One worker builds the wheel, once, for all three tests.
pytestmark = pytest.mark.xdist_group("install")


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding wxsky installed from a freshly built wheel (dependencies stay the
    venv's own, so no network is needed). The wheel is built from a copy of the package:
    setuptools writes build/ and wxsky.egg-info beside what it builds, and the checkout's
    may be in use by another build or hold a stale one."""
    tmp = tmp_path_factory.mktemp("install")
    source = tmp / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, source / name)
    shutil.copytree(
        ROOT / "wxsky", source / "wxsky", ignore=shutil.ignore_patterns("__pycache__", "*.pyc")
    )
    wheels = tmp / "wheels"
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    built = subprocess.run(
        [*pip, "wheel", "--no-deps", "--no-build-isolation", "-w", str(wheels), str(source)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    if built.returncode != 0:
        said = [ln for ln in built.stderr.splitlines() if "rror" in ln] or built.stderr.splitlines()
        pytest.skip(f"cannot build a wheel here: {' | '.join(said[-4:])}")
    (wheel,) = wheels.glob("wxsky-*.whl")
    target = tmp / "site"
    subprocess.run(
        [*pip, "install", "--no-deps", "--target", str(target), str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    return target


def run_installed(site: Path, *args: str, home: Path) -> subprocess.CompletedProcess[str]:
    # From "/", with the installed copy first on the path: nothing may come from the checkout.
    env = {**os.environ, "PYTHONPATH": str(site), "HOME": str(home), "XDG_CONFIG_HOME": ""}
    return subprocess.run(
        [sys.executable, *args], cwd="/", env=env, capture_output=True, text=True, timeout=300
    )


def test_the_installed_copy_is_the_one_imported(installed: Path, tmp_path: Path) -> None:
    proc = run_installed(installed, "-c", "import wxsky; print(wxsky.__file__)", home=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert Path(proc.stdout.strip()).is_relative_to(installed)


def test_installed_presets_and_models_are_found_from_anywhere(
    installed: Path, tmp_path: Path
) -> None:
    shown = run_installed(
        installed, "-m", "wxsky", "preset", "show", "overcast-stratus", home=tmp_path
    )
    assert shown.returncode == 0, shown.stderr
    assert "nimbostratus" in shown.stdout or "stratus" in shown.stdout
    listed = run_installed(installed, "-m", "wxsky", "preset", "list", home=tmp_path)
    assert listed.returncode == 0, listed.stderr
    names = {line.split()[0] for line in listed.stdout.splitlines() if line.strip()}
    shipped = {p.stem for p in (ROOT / "wxsky" / "settings" / "presets").glob("*.toml")}
    assert shipped <= names
    code = (
        "from wxsky.scene.cloud_model_files import default_models;"
        "from wxsky.inputs.station_table import station_table;"
        "from wxsky.inputs.drivers import load_driver;"
        "m = default_models(); print(m.source, len(station_table()) > 1000,"
        " load_driver('serial').__name__)"
    )
    proc = run_installed(installed, "-c", code, home=tmp_path)
    assert proc.returncode == 0, proc.stderr
    source, many, driver = proc.stdout.split()
    assert Path(source).is_relative_to(installed) and many == "True" and driver == "SerialLink"


@pytest.mark.gl
def test_an_installed_snapshot_renders_from_root(installed: Path, tmp_path: Path) -> None:
    out = tmp_path / "storm.png"
    proc = run_installed(
        installed,
        "-m",
        "wxsky",
        "snapshot",
        "--preset",
        "thunderstorm",
        "--size",
        "160x90",
        "--out",
        str(out),
        home=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    from wxsky.png import read_png

    image = read_png(out)
    assert image.shape == (90, 160, 4)
    assert image[..., :3].std() > 5.0  # a sky with clouds, not a blank frame
